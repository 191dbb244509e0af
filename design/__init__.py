"""Gains designed for the guarantees (docs/synthesis.md, 'Design'; ``make design``).

The observer's gains come from :mod:`synthesis.design` (LMIs (15), (16) as GEVPs, pure
math); the controller's are chosen here, from Theorem 2's closed-form constants
(:func:`verify.bounds.theorem2_constants`, the provable variant the verifier uses), and
each candidate is simulated and verified (:mod:`generated.api`, :mod:`verify.pipeline`)
to check the torque budget and measure its guarantees: this loop needs both layers, so
it sits above them.
"""
