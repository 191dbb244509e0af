"""The step-count diagnostics (benchmarks/steps.py).

The small two-follower scenario of test_sim_api (0.5 s, a fault at 0.3 s) compiled
with -O0 into a temporary build root keeps this fast.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import SMALL

from benchmarks.steps import (
    default_edges,
    knob_sensitivity,
    main,
    parse_vary,
    step_profile,
    u0_sign_change_times,
    windows_frame,
)
from core.errors import IntegrationError, UsageError, run_cli
from core.scenario import load_scenario
from generated import api
from generated.values import CodegenSettings

PAPER = "scenarios/paper.toml"


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("steps")
    path = root / "small.toml"
    path.write_text(SMALL)
    cg = CodegenSettings(optimization="-O0", build_root=str(root / "build"))
    sc = api.load(path)
    gains, _ = api.ensure_gains(sc, root / "out")
    return {
        "path": path,
        "sc": sc,
        "built": api.build(sc, gains, settings=cg),
        "cg": cg,
        "out": root / "out",
    }


def test_default_edges():
    e = default_edges(20.0)
    assert e[0] == 0.0 and e[-1] == 20.0
    assert np.all(np.diff(e) > 0)
    assert {0.01, 0.1, 1.0, 19.0} <= set(e.tolist())
    assert default_edges(0.05).tolist() == [0.0, 0.01, 0.03, 0.05]
    with pytest.raises(IntegrationError, match="horizon"):
        default_edges(float("nan"))


def test_u0_sign_changes_of_the_paper_command_are_those_of_cos():
    """u0 = 2 cos t changes sign at π/2 + kπ: six times in 20 s."""
    times = u0_sign_change_times(load_scenario(PAPER), 20.0)
    want = np.pi / 2 + np.pi * np.arange(6)
    assert len(times) == 6
    np.testing.assert_allclose(times, want, atol=1.001e-3)


def test_step_profile_tiles_the_run(small):
    sc, built = small["sc"], small["built"]
    assert api.breakpoints(built, sc) == [0.3]  # the fault onset of follower 1
    edges = default_edges(sc.integration.horizon)
    wins = step_profile(built, sc, edges)
    assert [w.start for w in wins] == edges[:-1].tolist()
    assert [w.end for w in wins] == edges[1:].tolist()
    assert all(w.steps > 0 and w.rhs_evals >= w.steps for w in wins)
    assert all(math.isfinite(w.last_step) and 0 < w.last_step <= w.end - w.start for w in wins)
    one = api.simulate(built, sc)
    # restarts at every edge only add work
    assert sum(w.steps for w in wins) >= one.stats["steps"]
    wf = windows_frame(wins)
    assert len(wf) == len(wins) and (wf["steps_per_s"] > 0).all()
    # u0 = 2 cos t has no sign change before 0.5 s
    assert not wf["u0_sign_change"].any() and wf["since_u0_sign_change"].isna().all()


def test_step_profile_final_state_matches_one_run(small):
    from generated.solvers.engine import integrate

    sc, built = small["sc"], small["built"]
    s = api.integrator_settings(sc)
    x0 = np.asarray(built.closed_loop.x0, dtype=float)
    one = integrate(built.dyn, x0, np.array([0.0, 0.5]), s, breakpoints=[0.3])
    x = x0
    for a, b in [(0.0, 0.1), (0.1, 0.3), (0.3, 0.5)]:
        x = integrate(built.dyn, x, np.array([a, b]), s, breakpoints=[0.3]).x[-1]
    scale = 1.0 + np.abs(one.x[-1])
    assert np.max(np.abs(x - one.x[-1]) / scale) < 1e-5


def test_bad_edges_are_rejected(small):
    with pytest.raises(IntegrationError, match="edges"):
        step_profile(small["built"], small["sc"], [0.1, 0.2])


def test_knob_sensitivity_reruns_with_one_field_changed(small):
    kf = knob_sensitivity(
        small["path"], [("integration.horizon", (0.2,))], small["out"], codegen=small["cg"]
    )
    assert kf["key"].tolist() == ["(file)", "integration.horizon"]
    assert kf["complete"].all()
    assert kf["t_reached"].tolist() == [0.5, 0.2]
    assert kf["steps"][1] < kf["steps"][0]
    assert np.isfinite(kf[["tail_eeta", "tail_et"]].to_numpy()).all()


def test_parse_vary():
    assert parse_vary("observer.phi_min=0.001, 0.05") == ("observer.phi_min", (0.001, 0.05))
    assert parse_vary('options.sign="sat"') == ("options.sign", ("sat",))
    for bad in ("phi_min", "=1", "a.b=", "a.b=nan nan"):
        with pytest.raises(UsageError):
            parse_vary(bad)


def test_cli_errors_are_one_line(capsys):
    assert run_cli(main, ["--bench-n", "0"]) == 2
    assert run_cli(main, ["--vary", "observer.phi_min"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("error: ") for e in err)


def test_cli_profiles_a_benchmark_scenario(tmp_path, capsys):
    """``--bench-n`` profiles the benchmark's random-graph scenario and writes the CSV."""
    import pandas as pd

    assert main(["--bench-n", "2", "--no-knobs", "--out", str(tmp_path)]) == 0
    wf = pd.read_csv(tmp_path / "steps_windows.csv")
    assert wf["end"].iloc[-1] == 20.0 and (wf["steps"] > 0).all()
    assert not (tmp_path / "steps_knobs.csv").exists()
    out = capsys.readouterr().out
    assert "N = 2" in out and "one uninterrupted run" in out


def test_cli_knob_table_and_variant_gains_stay_in_the_output_folder(small, tmp_path):
    import pandas as pd

    out = tmp_path / "steps"
    assert main([str(small["path"]), "--vary", "integration.horizon=0.2", "--out", str(out)]) == 0
    kf = pd.read_csv(out / "steps_knobs.csv")
    assert kf["key"].tolist() == ["(file)", "integration.horizon"]
    assert (out / "steps_windows.csv").is_file()
    assert sorted(p.name for p in (out / "variants").iterdir()) == ["small", "small-horizon-0.2"]
