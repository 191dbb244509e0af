"""Certified synthesis: assumptions, Lemma 3, LMIs (15)–(16), gains and their certificate."""
