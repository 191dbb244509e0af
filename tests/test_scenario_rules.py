"""Rules between settings hold for every Scenario, however it is made.

The loader, :func:`dataclasses.replace` and ``generated.api.with_method`` all go
through :meth:`core.scenario.Scenario.validate`; a scenario that breaks a
documented rule (docs/scenario-format.md) cannot be held in memory.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import PAPER

from core.errors import ScenarioError
from core.scenario import Integration, load_scenario
from generated import api
from generated.values import IntegratorSettings


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER)


def _exact_fixed(tmp_path: Path) -> Path:
    text = re.sub(r"(?m)^sign = .*$", 'sign = "exact"', PAPER.read_text(), count=1)
    text = re.sub(r"(?m)^method = .*$", 'method = "fixed"', text, count=1)
    path = tmp_path / "exact.toml"
    path.write_text(text)
    return path


def test_with_method_refuses_the_exact_sign_with_a_variable_step(tmp_path):
    sc = load_scenario(_exact_fixed(tmp_path))
    assert sc.options.sign == "exact" and sc.integration.method == "fixed"
    assert api.with_method(sc, "fixed") == sc
    for method in ("cvodes", "native", "idas"):
        with pytest.raises(ScenarioError, match=r"options\.sign: 'exact' makes"):
            api.with_method(sc, method)


def test_the_loader_and_replace_give_the_same_error(tmp_path):
    path = _exact_fixed(tmp_path)
    sc = load_scenario(path)
    text = path.read_text().replace('method = "fixed"', 'method = "native"', 1)
    path.write_text(text)
    with pytest.raises(ScenarioError) as from_file:
        load_scenario(path)
    ig = dataclasses.replace(sc.integration, method="native")
    with pytest.raises(ScenarioError) as from_replace:
        dataclasses.replace(sc, integration=ig)
    assert str(from_file.value) == str(from_replace.value)


@pytest.mark.parametrize(
    ("section", "changes", "key", "words"),
    [
        ("observer", {"delta1_hat": 0.5}, "observer.delta1_hat", "0.5 >= delta1 = 0.5"),
        ("observer", {"delta2_hat": 2.0}, "observer.delta2_hat", "2.0 >= delta2"),
        ("observer", {"phi_min": 1.0}, "observer.phi0", "phi0 must exceed phi_min"),
        ("controller", {"sigma": np.zeros(5)}, "controller.sigma", "needs sigma > 0"),
        ("integration", {"output_step": 30.0}, "integration.output_step", "exceeds the horizon"),
        ("integration", {"fixed_step": 21.0}, "integration.fixed_step", "exceeds the horizon"),
        ("integration", {"method": "rk4"}, "integration.method", "'rk4' is not allowed"),
        ("integration", {"rtol": 1.0}, "integration.rtol", "1.0 >= 1"),
        ("integration", {"max_steps": 0}, "integration.max_steps", "not positive"),
        ("controller", {"g_min": 1.5}, "controller.g_min", "outside (0, 1]"),
        ("options", {"feedforward": "yes"}, "options.feedforward", "not a boolean"),
        ("observer", {"lambda1": float("nan")}, "observer.lambda1", "not finite"),
    ],
)
def test_replace_cannot_make_an_invalid_scenario(paper, section, changes, key, words):
    part = dataclasses.replace(getattr(paper, section), **changes)
    with pytest.raises(ScenarioError) as info:
        dataclasses.replace(paper, **{section: part})
    msg = str(info.value)
    assert msg.startswith(f"{paper.path}: {key}:") and words in msg, msg


def test_replace_names_the_bad_entry_of_a_list(paper):
    lam = np.array(paper.controller.Lambda)
    lam[2, 1] = -1.0
    ctrl = dataclasses.replace(paper.controller, Lambda=lam)
    with pytest.raises(ScenarioError, match=r"controller\.Lambda\[2\]\[1\]: -1\.0 is not positive"):
        dataclasses.replace(paper, controller=ctrl)


def test_projection_needs_g_min_below_every_health(paper):
    opts = dataclasses.replace(paper.options, ghat_law="projection")
    ok = dataclasses.replace(paper, options=opts)  # g_min 0.5 <= g_i = 0.95
    assert ok.options.ghat_law == "projection"
    ctrl = dataclasses.replace(paper.controller, g_min=0.96)
    with pytest.raises(ScenarioError, match=r"controller\.g_min: 0\.96 exceeds .* 0\.95"):
        dataclasses.replace(paper, options=opts, controller=ctrl)


def test_integrator_defaults_are_the_scenario_defaults():
    s, ig = IntegratorSettings(), Integration()
    for name in ("method", "rtol", "atol", "max_steps", "fixed_step"):
        assert getattr(s, name) == getattr(ig, name), name
    assert (ig.method, ig.max_steps) == ("cvodes", 200000)  # docs/scenario-format.md
