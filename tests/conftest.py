"""Shared pytest set-up: repeatable property-based examples and shared fixtures.

Property-based tests draw the same examples on every run: a suite that must pass on a
clean machine cannot depend on which examples a random seed happens to draw;
``HYPOTHESIS_PROFILE=explore`` draws fresh ones (and more of them) when looking for new
failures by hand. Paths and closed-loop helpers shared by the modules are in
``tests/helpers.py``.
"""

import os

import pytest
from helpers import PAPER
from hypothesis import settings

from core.scenario import Scenario, load_scenario

settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture(scope="session")
def paper_scenario() -> Scenario:
    """The shipped paper scenario (``scenarios/paper.toml``), loaded once; it is frozen."""
    return load_scenario(PAPER)
