"""Shared pytest set-up: property-based tests draw the same examples on every run.

A suite that must pass on a clean machine cannot depend on which examples a random
seed happens to draw; ``HYPOTHESIS_PROFILE=explore`` draws fresh ones (and more of
them) when looking for new failures by hand.
"""

import os

from hypothesis import settings

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))
