"""Shared pytest set-up: repeatable property-based examples, the test tiers, shared fixtures.

Two tiers: ``make check`` runs the tests not marked ``slow`` (for the edit loop: the
loader, expressions, synthesis, docs and repository checks, verification on synthetic
trajectories), ``make test`` runs everything. A test is ``slow`` when it carries
``@pytest.mark.slow`` or belongs to a module of :data:`SLOW_MODULES`, whose tests compile
generated C or integrate whole scenarios.

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

#: test modules whose tests compile generated C, integrate whole scenarios, start
#: subprocesses or draw figures (``make test`` runs them; ``make check`` leaves them out)
SLOW_MODULES = frozenset(
    {
        "test_agents",
        "test_artifacts_trust",
        "test_bench",
        "test_bipartite",
        "test_breakpoints",
        "test_build_reuse",
        "test_cache_portable",
        "test_cache_private",
        "test_cli_knobs",
        "test_closed_loop",
        "test_console",
        "test_console_page",
        "test_console_replay",
        "test_definition1",
        "test_fault_slots",
        "test_faults",
        "test_generated_codegen",
        "test_generated_integrate",
        "test_input_limits",
        "test_native",
        "test_parameters",
        "test_planar",
        "test_saturation",
        "test_search",
        "test_shipped_scenarios",
        "test_sim_api",
        "test_solver_interface",
        "test_startup_caches",
        "test_steps",
        "test_study_inputs",
        "test_sundials_messages",
        "test_sweep_report",
        "test_sweep_run",
        "test_switching",
        "test_synthesis_cli",
        "test_theorem2_intervals",
        "test_topologies_study",
        "test_verify_lyapunov",
        "test_verify_report",
        "test_verify_rows",
    }
)

#: single tests of quick modules that take tens of seconds (a large sample's statistics) or
#: start a subprocess
SLOW_TESTS: frozenset[str] = frozenset({"test_certify_refuses_dev_zero_and_a_fifo_unread"})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test of :data:`SLOW_MODULES`, and those of :data:`SLOW_TESTS`, ``slow``.

    Parameters
    ----------
    config : pytest.Config
    items : list of pytest.Item
    """
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if item.module is not None else ""
        if module in SLOW_MODULES or item.originalname in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def paper_scenario() -> Scenario:
    """The shipped paper scenario (``scenarios/paper.toml``), loaded once; it is frozen."""
    return load_scenario(PAPER)


@pytest.fixture
def stored_designs(tmp_path_factory, monkeypatch):
    """A design.json with no keys (the scenario's own gains) for every shipped scenario with
    a ``[design]`` table, in a temporary output root that ``design.run`` reads: the shipped
    studies on such a base load without running ``make design``."""
    import json
    import tomllib

    import design.run as R
    from core.overrides import load

    root = tmp_path_factory.mktemp("designs")
    for path in sorted(PAPER.parent.glob("*.toml")):
        if "design" not in tomllib.loads(path.read_text(encoding="utf-8")):
            continue
        sc = load(path)
        rec = {
            "format": R.FORMAT,
            "scenario_sha256": sc.sha256,
            "procedure_sha256": R.procedure_sha256(),
            "overrides": {},
        }
        (root / f"{sc.name}-{R.VARIANT}").mkdir()
        (root / f"{sc.name}-{R.VARIANT}" / "design.json").write_text(json.dumps(rec))
    monkeypatch.setattr(R, "OUT_ROOT", root)
    return root
