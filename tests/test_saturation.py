"""Actuator saturation ``controller.u_max``: the applied torque is the hard clip sat(u_i).

Truth used here: ``numpy.clip`` of the unsaturated control law's torque (a direct
computation), the follower dynamics (2) written with the model's own M(p_i), the
numpy reference loop (verify/reference.py), and the paper trajectory's bytes with
and without a limit no torque reaches (the option off must not change the loop).
"""

from __future__ import annotations

import dataclasses
import hashlib
import subprocess
import sys

import numpy as np
import pytest
from helpers import PAPER, ROOT, simulate_paper

from core.errors import ScenarioError
from core.models import build_model
from core.scenario import load_scenario
from symbolic.closed_loop import build_closed_loop
from verify.lyapunov import check_theorem2
from verify.reference import Reference, hand_gains
from verify.report import saturation_statement
from verify.table import SATURATION_NOTE, bounds_table, failures, mark_saturation

TOL = {"abstol": 1e-8, "reltol": 1e-8, "max_num_steps": 500000}
U_MAX = 200.0  # N·m: far below the paper run's start-up peaks (about 2e5 to 2e6)


def _limited(sc, u_max):  # noqa: ANN001, ANN202
    """``sc`` with ``controller.u_max`` (validated again by ``dataclasses.replace``)."""
    ctrl = dataclasses.replace(sc.controller, u_max=np.asarray(u_max, dtype=float))
    return dataclasses.replace(sc, controller=ctrl)


def _signals(cl, t: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(ẋ, logged u as N×n) of closed loop ``cl`` at (t, x)."""
    xdot = np.asarray(cl.ode(t, x)).ravel()
    outs = dict(zip(cl.outputs.name_out(), cl.outputs(t, x), strict=True))
    return xdot, np.asarray(outs["u"])


def test_saturated_rhs_is_the_unsaturated_one_with_the_torque_clipped():
    sc = load_scenario(PAPER)
    g = hand_gains(sc)
    free = build_closed_loop(sc, g)
    rng = np.random.default_rng(7)
    x = np.asarray(free.x0).ravel() + 0.05 * rng.standard_normal(free.layout.nx)
    t = 0.3
    xdot, u = _signals(free, t, x)
    peak = np.abs(u).max(axis=1)
    # follower 1 stays below its limit, the others are clipped in at least one component
    u_max = np.concatenate([[2.0 * peak[0]], 0.5 * peak[1:]])
    sat = _limited(sc, u_max)
    cl = build_closed_loop(sat, g)
    xdot_s, u_s = _signals(cl, t, x)
    want = np.clip(u, -u_max[:, None], u_max[:, None])
    assert np.array_equal(u_s, want)  # the logged torque is exactly the clipped law
    assert np.all(np.abs(u_s) <= u_max[:, None])
    lay = cl.layout
    for i, fo in enumerate(sc.followers):
        sl = lay.slices[("q", i)]
        if i == 0:  # below the limit: the same right-hand side, bit for bit
            assert np.array_equal(xdot_s[sl], xdot[sl])
            continue
        # eq. (2): M (q̇_sat − q̇) = g_i (sat(u_i) − u_i); M from the model itself
        M = np.asarray(build_model(fo.model, fo.params).M(x[lay.slices[("p", i)]]))
        gi = float(fo.g.expr.casadi(t))
        lhs = M @ (xdot_s[sl] - xdot[sl])
        rhs = gi * (want[i] - u[i])
        assert np.allclose(lhs, rhs, rtol=1e-9, atol=1e-9 * np.abs(u[i]).max())
    # every other state's rate is unchanged: the limit acts on the torque only
    qs = np.concatenate([np.arange(lay.nx)[lay.slices[("q", i)]] for i in range(sc.N)])
    rest = np.setdiff1d(np.arange(lay.nx), qs)
    assert np.array_equal(xdot_s[rest], xdot[rest])
    # the numpy reference implements the same clip
    ref = Reference(sat, g).evaluate(t, x)
    assert np.allclose(ref["u"], want, rtol=1e-10, atol=1e-10)
    assert np.allclose(ref["xdot"], xdot_s, rtol=1e-9, atol=1e-9 * np.abs(xdot_s).max())


@pytest.fixture(scope="module")
def saturated_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    grid = np.linspace(0.0, 1.0, 101)
    over = {"controller.u_max": U_MAX, "integration.horizon": 1.0}
    return simulate_paper(over, "test-saturation", out, grid, TOL)


def test_short_saturated_run_reaches_the_horizon_within_the_limit(saturated_run):
    r = saturated_run
    assert r.t[-1] == pytest.approx(1.0)
    assert np.all(np.isfinite(r.X))
    u = r.frame().filter(regex=r"^u\d+_\d+$").to_numpy(float)
    assert u.shape[1] == r.sc.N * r.sc.n
    assert np.abs(u).max() <= U_MAX  # a hard clip: no smoothing tolerance
    assert np.isclose(np.abs(u), U_MAX, rtol=1e-12).any()  # and the limit is reached


def test_report_marks_the_rows_saturation_invalidates(saturated_run, tmp_path):
    r = saturated_run
    df = r.frame()
    checks = check_theorem2(r.cl, r.sc, r.t, r.X)
    tb = bounds_table(r.sc, df, gains=r.gains, theorem2=checks)
    marked = tb[tb["note"].str.startswith(SATURATION_NOTE)]
    cons = tb[tb["claim"].str.startswith("consistency: (38)")]
    assert len(cons) == r.sc.N and cons.index.isin(marked.index).all()
    # (38) does fail once the torque is clipped: without the marking check would exit 1
    assert not cons["holds"].all()
    assert set(marked["kind"]) == {"info"} and failures(tb, strict=True).empty
    for prefix in ("T2 ", "Lemma 1 ", "Lemma 2 ", "Def. 1 "):
        rows = tb[tb["claim"].str.startswith(prefix)]
        assert not rows.empty and rows.index.isin(marked.index).all(), prefix
    unmarked = tb[~tb.index.isin(marked.index)]
    assert unmarked["claim"].str.startswith(("T1 ", "peak |u_i|", "peak |u_i*|", "Formation")).all()
    assert "saturation" in " ".join(saturation_statement(tb))
    # an unsaturated run of the same scenario: no row marked, no sentence
    free = simulate_paper({"integration.horizon": 1.0}, "test-saturation-free", tmp_path, r.t, TOL)
    tf = bounds_table(free.sc, free.frame(), gains=free.gains)
    assert not tf["note"].str.startswith(SATURATION_NOTE).any()
    assert saturation_statement(tf) == []


def test_a_limit_never_reached_leaves_the_rows_unchanged(saturated_run, tmp_path):
    r = saturated_run
    high = simulate_paper(
        {"controller.u_max": 1e9, "integration.horizon": 1.0}, "test-sat-high", tmp_path, r.t, TOL
    )
    tb = bounds_table(high.sc, high.frame(), gains=high.gains)
    assert not tb["note"].str.startswith(SATURATION_NOTE).any()
    assert tb.equals(mark_saturation(tb, None))


def test_marking_turns_guaranteed_rows_into_info_and_keeps_the_rest():
    import pandas as pd

    rows = [  # the rule reads the registry's dependencies, by claim id
        ("t2.chi.provable", "guaranteed", False, "x"),
        ("def1.derived", "guaranteed", True, ""),
        ("t2.eq38", "consistency", False, "y"),
        ("t1.tail", "guaranteed", False, "z"),
    ]
    tb = pd.DataFrame(rows, columns=["claim_id", "kind", "holds", "note"])
    out = mark_saturation(tb, (0.0, 0.5))
    assert list(out["kind"]) == ["info", "info", "info", "guaranteed"]
    assert out["note"][0] == f"{SATURATION_NOTE} [0, 0.5] s; x"
    assert out["note"][1] == f"{SATURATION_NOTE} [0, 0.5] s"
    assert out["note"][3] == "z" and list(tb["kind"])[0] == "guaranteed"


def _paper_text_with(line: str) -> str:
    text = PAPER.read_text()
    assert text.count("[controller]\n") == 1
    return text.replace("[controller]\n", f"[controller]\n{line}\n")


@pytest.mark.parametrize("value", ["0.0", "-1.0", "nan", "inf", '"off"', "[1.0, 2.0]"])
def test_bad_limits_get_a_one_line_error(tmp_path, value):
    path = tmp_path / "bad.toml"
    path.write_text(_paper_text_with(f"u_max = {value}"))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg and "controller.u_max" in msg and "expected" in msg


def test_bad_limit_on_the_command_line_is_one_line_and_exit_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(_paper_text_with("u_max = nan"))
    cmd = [sys.executable, "-m", "generated", "sim", str(path), "--out", str(tmp_path / "o")]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "controller.u_max" in lines[0]
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").rglob("*.csv"))


def test_paper_trajectory_is_unchanged_by_an_inactive_limit(tmp_path):
    """Default (no limit) and a limit no torque reaches give the same bytes, in one run.

    The paper run's peaks are about 2e6 N·m, so ``u_max = 1e30`` never clips and
    fmin/fmax return their argument exactly: any difference means the option leaks
    into the unsaturated loop. Both runs share the machine and the synthesised gains,
    so the comparison does not depend on which CPU computes it.
    """
    limited = tmp_path / "limited.toml"
    limited.write_text(_paper_text_with("u_max = 1e30"))
    data = []
    for path, out in ((PAPER, tmp_path / "free"), (limited, tmp_path / "limited")):
        cmd = [sys.executable, "-m", "generated", "sim", str(path), "--out", str(out)]
        subprocess.run(
            [*cmd, "--no-progress"], cwd=ROOT, check=True, capture_output=True, timeout=600
        )
        data.append((out / "paper" / "trajectory.csv").read_bytes())
    traj = np.loadtxt(tmp_path / "free" / "paper" / "trajectory.csv", delimiter=",", skiprows=1)
    assert traj.shape[0] > 100 and np.isfinite(traj).all()
    assert hashlib.sha256(data[0]).hexdigest() == hashlib.sha256(data[1]).hexdigest()


def test_none_and_per_follower_values_load(tmp_path):
    path = tmp_path / "limits.toml"
    path.write_text(_paper_text_with('u_max = "none"'))
    assert load_scenario(path).controller.u_max is None
    path.write_text(_paper_text_with("u_max = [10.0, 20.0, 30.0, 40.0, 50.0]"))
    assert np.array_equal(load_scenario(path).controller.u_max, [10.0, 20.0, 30.0, 40.0, 50.0])
    path.write_text(_paper_text_with("u_max = 7"))
    assert np.array_equal(load_scenario(path).controller.u_max, np.full(5, 7.0))


def test_agent_blocks_apply_the_same_limit():
    """One follower's block (the per-agent engine's kernels) clips like the whole closed loop.

    Passes by jet level over all followers (as generated/native/agents.c does): the
    level-l jet reads only the levels < l of the neighbours' sum, so three passes give
    every block its exact input on any graph.
    """
    from symbolic.cascade import agent_block
    from symbolic.closed_loop import make_layout, observer_gains
    from symbolic.network import graph_matrices
    from symbolic.parameters import agent_rows

    sc = load_scenario(PAPER)
    g = hand_gains(sc)
    sat = _limited(sc, np.full(sc.N, 50.0))
    cl = build_closed_loop(sat, g)
    lay = make_layout(sat.m, sat.n, sat.N, False)
    m, na, n, N = lay.m, lay.agent_size, sat.n, sat.N
    block = agent_block(sat, observer_gains(sat, g), lay, 0)
    gm = graph_matrices(sat.graph, g)
    off = gm.L_B - np.diag(np.diag(gm.L_B))
    cpl = np.column_stack([np.diag(gm.L_B), gm.a0h, np.zeros((N, 4))])  # no fade: no rates
    prm = agent_rows(sat, observer_gains(sat, g)).T  # the blocks evaluate g_i, f_i from them
    x = np.asarray(cl.x0).ravel()
    t = 0.0
    xd, u = _signals(cl, t, x)
    assert np.isclose(np.abs(u), 50.0, rtol=1e-12).any()  # the limit is active here
    jets = np.zeros((N, 3 * n))
    for _ in range(3):  # pass l fixes the level-l jets
        nb = off @ jets
        outs = [
            block(
                t,
                np.concatenate([x[:m], x[m + i * na : m + (i + 1) * na]]),
                nb[i],
                cpl[i],
                prm[:, i],
            )
            for i in range(N)
        ]
        jets = np.array([np.array(o[1]).ravel() for o in outs])
    for i, out in enumerate(outs):
        want = np.concatenate([xd[:m], xd[m + i * na : m + (i + 1) * na]])
        np.testing.assert_allclose(np.array(out[0]).ravel(), want, rtol=1e-12, atol=1e-12)
