"""Certified synthesis: assumptions, Lemma 3, LMIs (15)–(16), gains and their certificate."""

from synthesis.api import synthesize
from synthesis.certificate import certify
from synthesis.gains import Gains, load_gains, save_gains

__all__ = ["Gains", "certify", "load_gains", "save_gains", "synthesize"]
