"""The planar operator (``scenarios/planar.toml``): a leader with two inputs.

Truth used here, independent of the code under test:

* the leader is two decoupled copies of v̇ = −c v + u, y = x + v, whose transfer function
  (s + 1)/(s(s + c)) gives the invariant zeros −1, −1 by hand;
* the certificate of the gains is recomputed in numpy from the matrices alone: the
  eigenvalues of the LMI matrices (15)–(16) and of the closed-loop matrices they certify,
  Lemma 3's w from the graph, and the block matrix whose negativity k1 is chosen for
  (Theorem 1's proof, eq. (27)) — each check is also shown to fail on a spoilt gain;
* the leader's trajectory of a run against an independent integration of eq. (3).
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla
from helpers import ROOT, SCENARIOS
from scipy.integrate import solve_ivp

from core.errors import ScenarioError, SynthesisError
from core.scenario import load_scenario
from sweep.sampler import scenario_toml
from verify.reference import _dual

PLANAR = SCENARIOS / "planar.toml"
DRAG = 0.5  # the scenario's velocity drag c: A0[2, 2] = A0[3, 3] = −c


@pytest.fixture(scope="module")
def planar():
    return load_scenario(PLANAR)


@pytest.fixture(scope="module")
def gains(planar):
    """Gains solved here with cvxpy (Clarabel), not read from a cache."""
    from synthesis import synthesize

    return synthesize(planar)


# ----------------------------------------------------------------------------- leader
def test_leader_is_planar_with_two_inputs(planar):
    L = planar.leader
    assert (planar.m, planar.p, planar.n) == (4, 2, 2)
    # two decoupled axes: G(s) = C0 (sI − A0)⁻¹ B0 = diag((s + 1)/(s (s + c))) at any s
    for s in (0.7, 2.0 + 1.5j, -3.1):
        G = L.C0 @ np.linalg.solve(s * np.eye(4) - L.A0, L.B0)
        np.testing.assert_allclose(G, np.eye(2) * (s + 1) / (s * (s + DRAG)), rtol=1e-12)
    # both inputs step in the shipped command, and ‖u0‖ stays within α (Euclidean norm)
    t = np.linspace(0.0, planar.integration.horizon, 20001)
    u = L.u0_numpy(t)
    assert np.ptp(u[0]) > 1.0 and np.ptp(u[1]) > 1.0
    assert np.linalg.norm(u, axis=0).max() <= L.alpha


def test_assumption2_holds_with_the_zeros_found_by_hand(planar, gains):
    from synthesis.assumptions import check_leader

    L = planar.leader
    assert np.linalg.matrix_rank(L.C0 @ L.B0) == np.linalg.matrix_rank(L.B0) == 2
    # square system: the invariant zeros are the finite eigenvalues of the Rosenbrock pencil
    E = sla.block_diag(np.eye(4), np.zeros((2, 2)))
    F = np.block([[L.A0, -L.B0], [L.C0, np.zeros((2, 2))]])
    ev = sla.eigvals(F, E)
    zeros = np.sort_complex(ev[np.isfinite(ev) & (np.abs(ev) < 1e6)])
    np.testing.assert_allclose(zeros, [-1.0, -1.0], atol=1e-6)
    lc = check_leader(L.A0, L.B0, L.C0)
    np.testing.assert_allclose(np.sort_complex(lc.zeros), zeros, atol=1e-6)
    np.testing.assert_allclose(
        [complex(*z) for z in gains.info["invariant_zeros"]], [-1.0, -1.0], atol=1e-6
    )


# ----------------------------------------------------------------------------- certificate
def recheck(sc, g) -> dict[str, float]:
    """Margins of every claim the gains rest on, recomputed in numpy (> 0: the claim holds).

    Parameters
    ----------
    sc : Scenario
    g : synthesis.gains.Gains
    """
    A0, B0, C0 = (np.asarray(M, float) for M in (sc.leader.A0, sc.leader.B0, sc.leader.C0))
    m, N = A0.shape[0], sc.N
    T, Om, Th, Q = g.T, g.Omega, g.Theta, g.Q
    out = {}
    out["T > 0"] = np.linalg.eigvalsh(T).min()
    F15 = A0 @ T + T @ A0.T - g.lambda_bar1 * B0 @ B0.T + g.delta1 * T  # eq. (15)
    out["LMI (15)"] = -np.linalg.eigvalsh(F15).max()
    out["Q = B0' T^-1"] = 1e-9 - np.abs(Q - B0.T @ np.linalg.inv(T)).max()
    # (15) with B0 B0ᵀ = B0 Q T: A0 − (λ̄1/2) B0 Q has every eigenvalue left of −δ1/2
    out["A0 - lb1/2 B0 Q"] = -(np.linalg.eigvals(A0 - g.lambda_bar1 / 2 * B0 @ Q).real.max())
    out["A0 - lb1/2 B0 Q"] -= g.delta1 / 2
    CB = C0 @ B0
    Gam = B0 @ np.linalg.inv(CB.T @ CB) @ CB.T  # eq. (7)
    Phi = np.eye(m) - Gam @ C0
    out["Gamma, Phi (7)"] = 1e-9 - max(np.abs(Gam - g.Gamma).max(), np.abs(Phi - g.Phi).max())
    out["Phi B0 = 0"] = 1e-9 - np.abs(Phi @ B0).max()
    X = Phi @ A0 - Th @ C0
    out["Omega > 0"] = np.linalg.eigvalsh(Om).min()
    out["LMI (16)"] = -np.linalg.eigvalsh(X.T @ Om + Om @ X + g.delta2 * Om).max()  # eq. (16)
    out["Phi A0 - Theta C0"] = -np.linalg.eigvals(X).real.max() - g.delta2 / 2
    # Lemma 3 on L̄ = L + B (cooperative graph: H = I)
    Adj, pin = np.asarray(sc.graph.adjacency, float), np.asarray(sc.graph.pinning, float)
    Lb = np.diag(Adj.sum(1) + pin) - Adj
    out["L_bar"] = 1e-12 - np.abs(Lb - g.L_bar).max()
    z = np.diag(g.Z)
    out["Z diagonal > 0"] = min(z.min(), 1e-12 - np.abs(g.Z - np.diag(z)).max())
    Zh = np.diag(z**-0.5)
    w = np.linalg.eigvalsh(Zh @ (Lb.T @ g.Z + g.Z @ Lb) @ Zh).min()
    out["w of Lemma 3"] = 1e-9 - abs(w - g.w)
    out["lambda1 w > lambda_bar1"] = g.lambda1 * w - g.lambda_bar1  # Theorem 1
    out["lambda2 >= alpha"] = g.lambda2 - sc.leader.alpha  # Theorem 1, ‖u0‖ ≤ α ≤ λ2
    # k1: the cross-term block of V̇1 is negative definite (the Schur step before eq. (27))
    Eb = np.kron(g.Z, np.linalg.solve(T, X - A0))  # Ē = (Z H) ⊗ T⁻¹(ΦA0 − ΘC0 − A0), H = I
    Pinv = np.linalg.inv(T)
    block = np.block(
        [
            [-g.delta1_hat * np.kron(g.Z, Pinv), Eb],
            [Eb.T, -g.k1 * g.delta2_hat * np.kron(np.eye(N), Om)],
        ]
    )
    out["cross-term block < 0 (k1)"] = -np.linalg.eigvalsh(0.5 * (block + block.T)).max()
    return out


def test_certificate_rechecked_independently(planar, gains):
    """Certified by cvxpy + Clarabel, then every claim recomputed from the matrices alone."""
    assert gains.info["solver"] == "CLARABEL"
    assert {v["solver"] for v in gains.info["lmi_solvers"].values()} == {"CLARABEL"}
    assert gains.Q.shape == (2, 4) and gains.Theta.shape == (4, 2)
    margins = recheck(planar, gains)
    failed = {k: v for k, v in margins.items() if not v > 0}
    assert not failed, failed
    assert gains.certificate["passed"] and not gains.certificate["failures"]


@pytest.mark.parametrize(
    "spoil, claim",
    [
        (lambda g: {"Theta": np.zeros_like(g.Theta)}, "LMI (16)"),
        (lambda g: {"k1": 0.5 * g.k1}, "cross-term block < 0 (k1)"),
        (lambda g: {"lambda2": 0.9 * g.lambda2}, "lambda2 >= alpha"),
        (lambda g: {"lambda1": 0.9 * g.lambda_bar1 / g.w}, "lambda1 w > lambda_bar1"),
        (lambda g: {"T": 2.0 * g.T}, "Q = B0' T^-1"),
    ],
    ids=["Theta=0", "k1/2", "lambda2<alpha", "lambda1 small", "T doubled"],
)
def test_the_recheck_fails_on_a_spoilt_gain(planar, gains, spoil, claim):
    """Θ = 0 leaves ΦA0's eigenvalue 0 in place; k1 at half its choice breaks the Schur step."""
    assert not recheck(planar, replace(gains, **spoil(gains)))[claim] > 0


def test_gains_file_is_reused_only_after_recertification(planar, gains, tmp_path):
    from synthesis.gains import load_gains, save_gains
    from synthesis.gains_cache import ensure_gains

    path = tmp_path / planar.name / "gains.json"
    path.parent.mkdir()
    save_gains(gains, path)
    back = load_gains(path)
    for k in ("T", "Omega", "Theta", "Q", "Z"):
        np.testing.assert_array_equal(getattr(back, k), getattr(gains, k))
    reused, info = ensure_gains(planar, tmp_path)
    assert info.reused and recheck(planar, reused)["cross-term block < 0 (k1)"] > 0


@pytest.mark.parametrize("t", [2.5, 5.4, 11.7, 15.5])
def test_closed_loop_matches_the_numpy_reference_inside_the_shaped_steps(planar, gains, t):
    """The CasADi loop against verify.reference (chain rule by hand), with the certified 2×4 Q
    and 4×2 Θ, at times where a shaped step of one input or both is under way."""
    from symbolic.closed_loop import build_closed_loop
    from verify.reference import Reference

    cl, ref = build_closed_loop(planar, gains), Reference(planar, gains)
    ud = np.array([e[1] for e in (_dual(u.node, t) for u in planar.leader.u0)])
    assert np.any(ud != 0.0)  # u̇0 ≠ 0: the feed-forward differentiates the command here
    rng = np.random.default_rng(int(10 * t))
    lay = cl.layout
    for _ in range(2):
        x = cl.x0 + rng.normal(size=lay.nx)
        for i in range(lay.N):
            x[lay.slices[("phi", i)]] = rng.uniform(0.01, 1.0)
            x[lay.slices[("ghat", i)]] = rng.uniform(1.0, 2.0)
            x[lay.slices[("thetahat", i)]] = rng.uniform(0.0, 3.0, 2)
        got, want = np.array(cl.ode(t, x)).ravel(), ref.rhs(t, x)
        for name in lay.agent_offsets:  # each block relative to its own size
            idx = np.concatenate([np.arange(lay.nx)[lay.slices[(name, i)]] for i in range(lay.N)])
            scale = max(np.abs(want[idx]).max(), 1.0)
            assert np.abs(got[idx] - want[idx]).max() <= 1e-10 * scale, name
        np.testing.assert_allclose(got[: lay.m], want[: lay.m], rtol=1e-12, atol=1e-12)


# ----------------------------------------------------------------------------- refusals
def _table() -> dict:
    return tomllib.loads(PLANAR.read_text(encoding="utf-8"))


def _write(tmp_path, data: dict, name: str = "bad.toml"):
    path = tmp_path / name
    path.write_text(scenario_toml(data), encoding="utf-8")
    return path


def test_input_bound_is_the_euclidean_norm_of_both_inputs(tmp_path):
    """Each component 1.6 < α = 2, but ‖u0‖ = 2.26 > α: refused on load, in one line."""
    data = _table()
    data["leader"]["u0"] = ["1.6*step(t - 2)", "1.6*step(t - 3)"]
    with pytest.raises(ScenarioError) as exc:
        load_scenario(_write(tmp_path, data))
    msg = str(exc.value)
    assert "\n" not in msg and "leader.alpha" in msg and "2.26274" in msg
    data["leader"]["alpha"] = 2.3  # the same command under a bound that covers it
    assert load_scenario(_write(tmp_path, data, "ok.toml")).leader.alpha == 2.3


def test_two_column_trace_beyond_alpha_is_refused(tmp_path):
    (tmp_path / "u0.csv").write_text("t,ux,uy\n0,0,0\n5,1.5,1.5\n20,0,0\n", encoding="utf-8")
    data = _table()
    del data["leader"]["u0"], data["leader"]["u0_rise"]
    data["leader"]["u0_csv"] = "u0.csv"
    with pytest.raises(ScenarioError) as exc:
        load_scenario(_write(tmp_path, data))
    assert "\n" not in str(exc.value) and "leader.alpha" in str(exc.value)
    assert "2.12132" in str(exc.value)  # ‖(1.5, 1.5)‖ at the row t = 5


@pytest.mark.parametrize(
    "C0, text",
    [
        # position only: C0 B0 = 0, the natural planar output without the velocity
        ([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]], "rank(C0 B0) = 0, rank(B0) = 2, p = 2"),
        # y = x − v on the first axis: zero at +1, no stable unknown-input observer
        ([[1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 1.0]], "invariant zero(s) 1 "),
    ],
    ids=["C0B0=0", "zero at +1"],
)
def test_assumption2_failure_is_refused_by_synthesis(planar, tmp_path, C0, text):
    from synthesis import synthesize

    bad = replace(planar, leader=replace(planar.leader, C0=np.array(C0)))
    with pytest.raises(SynthesisError) as exc:
        synthesize(bad)
    assert "Assumption 2 fails" in str(exc.value) and text in str(exc.value)
    assert "\n" not in str(exc.value)


def test_assumption2_failure_stops_make_synth_in_one_line(tmp_path):
    """The command line: exit status 2, one line on stderr, no gains file written."""
    C0 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]
    data = _table()
    data["leader"]["C0"] = C0
    out = tmp_path / "gains.json"
    cmd = [sys.executable, "-m", "synthesis", "synth", str(_write(tmp_path, data)), "--out"]
    proc = subprocess.run([*cmd, str(out)], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and not out.exists()
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Assumption 2 fails" in lines[0], proc.stderr


# ----------------------------------------------------------------------------- a run
#: presses and releases on both inputs, overlapping, shaped over 1 s (‖u0‖ ≤ 1.67 < α)
STEPS = {
    "leader.u0": [
        "1.4*step(t - 1) - 1.4*step(t - 6)",
        "-0.9*step(t - 3) + 1.9*step(t - 7.5) - 1.0*step(t - 10)",
    ],
    "leader.u0_rise": 1.0,
    "integration.horizon": 12.0,
}


@pytest.fixture(scope="module")
def steps_run(tmp_path_factory):
    from generated import api
    from generated.values import CodegenSettings
    from verify.pipeline import Run, verify_run

    root = tmp_path_factory.mktemp("planar")
    cg = CodegenSettings(optimization="-O0", jacobian="auto")
    res = api.run(
        PLANAR, overrides=STEPS, variant="steps", codegen=cg, out_root=root, progress=False
    )
    sc = api.load(PLANAR, STEPS, variant="steps")
    v = verify_run(Run(sc, res.frame, res.trajectory.x, res.meta, root), out_root=root)
    return sc, res, v.table


def test_both_inputs_drive_the_leader_of_the_run(steps_run):
    """The leader's states in trajectory.csv against eq. (3) integrated on its own."""
    sc, res, _ = steps_run
    df = res.frame
    L = sc.leader
    t = df["t"].to_numpy()
    assert res.trajectory.complete and t[-1] == 12.0
    ref = solve_ivp(
        lambda s, x: L.A0 @ x + L.B0 @ L.u0_numpy(s),
        (0.0, t[-1]),
        L.eta0,
        t_eval=t,
        rtol=1e-11,
        atol=1e-12,
        method="DOP853",
        max_step=0.05,
    )
    eta0 = df[[f"eta0_{k}" for k in range(1, 5)]].to_numpy()
    # the run's tolerances are rtol 1e-6, atol 1e-8 on states of size <= 10
    np.testing.assert_allclose(eta0, ref.y.T, atol=1e-4)
    # the heading of (vx, vy) turns: the formation is rotated in the plane
    heading = np.unwrap(np.arctan2(eta0[:, 3], eta0[:, 2])[t >= 2.0])
    assert np.ptp(heading) > np.pi / 2
    y0 = eta0 @ L.C0.T
    assert np.ptp(y0[:, 0]) > 3.0 and np.ptp(y0[:, 1]) > 1.0


def test_guaranteed_rows_hold_and_torques_stay_bounded_after_the_steps(steps_run):
    sc, res, table = steps_run
    rows = table[table["kind"] == "guaranteed"]
    assert len(rows) >= 3 * sc.N + 1  # φ-floor V̇1, and per follower T2 χ, e_t and Def. 1
    assert rows["holds"].notna().all(), rows[rows["holds"].isna()]  # every row evaluated
    assert rows["holds"].astype(bool).all(), rows[~rows["holds"].astype(bool)]
    late = res.frame[res.frame["t"] >= 1.0]
    assert late.filter(regex=r"^u\d+_\d+$").abs().to_numpy().max() < 1e3
    # every follower on its rotated slot at the end: Def. 1's deviation in the tail
    formation = table[table["claim"].str.startswith("Formation |p_i")]
    assert len(formation) == sc.N and (formation["observed"] < 0.05).all()


# ----------------------------------------------------------------------------- console
def test_console_scenario_has_both_inputs_held_at_zero():
    """``python -m console serve scenarios/planar.toml`` starts from this table: two held
    inputs at rest, validated like a file (the compiled console loop is tested in
    tests/test_console.py)."""
    from console.scenario import console_scenario, console_table

    table = console_table(PLANAR)
    sc = console_scenario(PLANAR, table)
    assert sc.p == 2 and len(table["leader"]["u0"]) == 2
    np.testing.assert_array_equal(sc.leader.u0_numpy(np.linspace(0, 20, 5)), np.zeros((2, 5)))
    base = load_scenario(PLANAR)
    for k in ("A0", "B0", "C0", "eta0"):
        np.testing.assert_array_equal(getattr(sc.leader, k), getattr(base.leader, k))
    assert sc.leader.alpha == base.leader.alpha
