"""Exact Lyapunov derivatives (AD) and the Theorem 1/2 pointwise checks on a real closed loop.

A short stretch of the paper's closed loop is integrated with CVODES on the
symbolic model (no generated C, tight tolerances). The exact V̇ by AD is compared
with a central finite difference of V along that trajectory (only here, in the
test), and the Theorem 2 inequality is checked with the reconstructed adaptive law
and with the printed one (χᵀMΨ), which must make it fail. The per-structure
(t, x, p) Functions of the fast path are compared with the MX path (AD through the
closed loop with the numbers fixed) on that stretch and on two native runs of
studies/faults.toml samples that share one structure.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from helpers import integrate, paper_loop, printed_law_ode, trajectory_frame

from verify import lyapunov as L
from verify.bounds import theorem1_rates
from verify.lyapunov import (
    check_theorem1,
    check_theorem2,
    evaluate,
    lyapunov_derivative,
    outputs_at,
)

# start on the formation with the leader moving, so the stretch is smooth (the
# formation angle atan2(η̇_i) is defined from t = 0)
CALM = {
    "initial.start": "formation",
    "initial.eta": [0.0, 1.0],
    "leader.eta0": [0.0, 1.0],
    "integration.horizon": 1.0,
}
H = 1e-6  # finite-difference half step (test only)
T_CHECK = (0.01, 0.02, 0.03)


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    sc, gains, cl = paper_loop(CALM, "test-verify", tmp_path_factory.mktemp("out"))
    grid = sorted({0.0, *T_CHECK, *(t - H for t in T_CHECK), *(t + H for t in T_CHECK)})
    grid = np.array(grid)
    X = integrate(cl, grid, {"abstol": 1e-12, "reltol": 1e-12, "max_num_steps": 200000})
    return sc, gains, cl, grid, X


def _at(grid, when):
    return int(np.argmin(np.abs(grid - when)))


@pytest.mark.parametrize("name", ["V1", "V2"])
def test_exact_vdot_matches_finite_difference_along_trajectory(loop, name):
    sc, _, cl, grid, X = loop
    V, Vd = evaluate(lyapunov_derivative(cl, name), grid, X)
    V, Vd = V[:, :, 0], Vd[:, :, 0]
    for tc in T_CHECK:
        k, kp, km = _at(grid, tc), _at(grid, tc + H), _at(grid, tc - H)
        fd = (V[kp] - V[km]) / (grid[kp] - grid[km])
        # central difference: truncation error O(H²) (measured to shrink 10x per 3x smaller H
        # down to H = 1e-6, where it is ~1e-8 relative), integration error ~1e-12·V / H
        np.testing.assert_allclose(Vd[k], fd, rtol=1e-5, atol=1e-5 * np.abs(V[k]).max())


def test_theorem2_inequality_holds_for_the_reconstructed_law(loop):
    sc, _, cl, grid, X = loop
    checks = check_theorem2(cl, sc, grid, X)
    assert len(checks) == sc.N
    for chk in checks:
        assert chk.ok, chk.where()


def test_printed_adaptive_law_makes_theorem2_fail(loop):
    sc, _, cl, grid, X = loop
    checks = check_theorem2(cl, sc, grid, X, ode=printed_law_ode(sc, cl))
    failed = [c for c in checks if not c.ok]
    assert failed, "the printed law chi'M Psi should violate eq. (38)"
    assert "fails for follower" in failed[0].where()


def test_theorem1_decay_rate_supported(loop):
    sc, gains, cl, grid, X = loop
    r = theorem1_rates(sc, gains)
    assert r.supported <= r.printed
    chk = check_theorem1(cl, grid, X, r.supported)
    vals = outputs_at(cl, grid, X)
    assert chk.lhs.shape == grid.shape and np.all(np.isfinite(chk.lhs))
    # at t = 0 the observer has not moved yet: V1 > 0 and the check is evaluated there
    assert vals["V1"][0, 0, 0] > 0


def test_theorem1_rate_holds_without_the_phi_floor(tmp_path):
    """With φ_min = 0 (the paper's observer) V̇1 ≤ −δ̃V1 must hold with the supported rate."""
    sc, gains, cl = paper_loop({**CALM, "observer.phi_min": 0.0}, "test-verify-phi0", tmp_path)
    grid = np.linspace(0.0, 1.0, 21)
    X = integrate(cl, grid, {"abstol": 1e-10, "reltol": 1e-10, "max_num_steps": 200000})
    r = theorem1_rates(sc, gains)
    chk = check_theorem1(cl, grid, X, r.supported)
    assert chk.ok, chk.where()
    assert np.all(chk.lhs < 0)  # V1 strictly decreasing along the flow


def _loop_variant(tmp_path, overrides, variant):
    sc, _, cl = paper_loop({**CALM, **overrides}, variant, tmp_path)
    return sc, cl


def test_printed_controller_without_feedforward_breaks_theorem2(loop, tmp_path):
    """Section 9.2: eq. (29) as printed omits ḃ, b̈; with a rotating formation (38) then fails."""
    sc_ff, _, cl_ff, grid, X = loop
    sc, cl = _loop_variant(tmp_path, {"options.feedforward": False}, "test-verify-noff")
    assert cl.layout.nx == cl_ff.layout.nx
    checks = check_theorem2(cl, sc, grid, X)
    assert any(not c.ok for c in checks)


def test_lemma1_premise_does_not_follow_for_the_paper_law(loop, tmp_path):
    """Section 9.3: (38)'s first inequality holds, yet V̇2 ≤ −Ωv2 V2 + χv2 fails when ĝ − 1/g is large."""
    from verify.bounds import theorem2_constants

    sc, cl = _loop_variant(tmp_path, {"options.ghat_law": "paper"}, "test-verify-paperlaw")
    x = np.asarray(cl.x0, float).reshape(1, -1).copy()
    for i in range(sc.N):
        x[0, cl.layout.slices[("ghat", i)]] = 3.0  # far from 1/g = 1.053
    t = np.array([0.0])
    assert all(c.ok for c in check_theorem2(cl, sc, t, x))
    V, Vd = evaluate(lyapunov_derivative(cl, "V2"), t, x)
    gaps = []
    for i in range(sc.N):
        c = theorem2_constants(sc, i)
        gaps.append(Vd[0, i, 0] + c.Omega * V[0, i, 0] - c.chi_v)
    assert max(gaps) > 0


def test_states_read_back_from_the_trajectory_csv_columns(loop):
    """`verify check` reuses trajectory.csv: its state columns must rebuild x exactly."""
    from verify.pipeline import states_from_frame

    sc, _, cl, grid, X = loop
    df = trajectory_frame(sc, cl, grid, X)
    np.testing.assert_array_equal(states_from_frame(cl, sc, df), X)


# ------------------------------------------------- per-structure Functions against the MX path
def _mx_path(cl):
    """The same closed loop without its parametric Functions: verify's MX path."""
    return dataclasses.replace(cl, parametric=None)


def _assert_same(new: np.ndarray, old: np.ndarray) -> None:
    """Equal to rounding: |new − old| ≤ 1e-12 of the largest |old| (exactly equal when 0)."""
    scale = float(np.max(np.abs(old)))
    assert np.all(np.isfinite(new))
    assert np.max(np.abs(new - old)) <= 1e-12 * scale, np.max(np.abs(new - old)) / scale


def _assert_checks_equal(sc, gains, cl, t, X) -> None:
    """Theorem 1/2 sides and every output: fast path == MX path."""
    r = theorem1_rates(sc, gains)
    new1, old1 = (
        check_theorem1(cl, t, X, r.supported),
        check_theorem1(_mx_path(cl), t, X, r.supported),
    )
    _assert_same(new1.lhs, old1.lhs)
    _assert_same(new1.rhs, old1.rhs)
    assert np.array_equal(new1.holds, old1.holds)
    for new, old in zip(
        check_theorem2(cl, sc, t, X), check_theorem2(_mx_path(cl), sc, t, X), strict=True
    ):
        _assert_same(new.lhs, old.lhs)
        _assert_same(new.rhs, old.rhs)
        assert np.array_equal(new.holds, old.holds)
    new_o, old_o = outputs_at(cl, t, X), outputs_at(_mx_path(cl), t, X)
    assert new_o.keys() == old_o.keys()
    for k in old_o:
        _assert_same(new_o[k], old_o[k])


@pytest.mark.parametrize("name", ["V1", "V2"])
def test_fast_vdot_matches_finite_difference_along_trajectory(loop, name, monkeypatch):
    """The per-structure (t, x, p) Function's V̇ against a central difference of its own V."""
    monkeypatch.setattr(L, "COMPILE_FROM_USE", 10**9)
    L.clear_cache()
    sc, _, cl, grid, X = loop
    V, Vd = L.evaluate_p(L.fast_functions(cl), name, grid, X, cl.p0)[:2]
    V, Vd = V[:, :, 0], Vd[:, :, 0]
    for tc in T_CHECK:
        k, kp, km = _at(grid, tc), _at(grid, tc + H), _at(grid, tc - H)
        fd = (V[kp] - V[km]) / (grid[kp] - grid[km])
        np.testing.assert_allclose(Vd[k], fd, rtol=1e-5, atol=1e-5 * np.abs(V[k]).max())


def test_fast_path_equals_mx_path_on_the_paper_scenario(loop, monkeypatch):
    monkeypatch.setattr(L, "COMPILE_FROM_USE", 10**9)  # SX virtual machine
    L.clear_cache()
    sc, gains, cl, grid, X = loop
    _assert_checks_equal(sc, gains, cl, grid, X)
    assert not L.fast_functions(cl).compiled


def _separate_p(cl, name: str, extra: tuple[str, ...] = ()):
    """``(t, x, p) -> (V, V̇, *extra)`` for one V, its own Function: the straightforward form
    of the fast path's one Function."""
    outs_f, ode_f = cl.parametric.outputs.expand(), cl.parametric.ode.expand()
    t = ca.SX.sym("t")
    x, p = ca.SX.sym("x", outs_f.size_in(1)), ca.SX.sym("p", outs_f.size_in(2))
    outs = dict(zip(outs_f.name_out(), outs_f.call([t, x, p]), strict=True))
    V = ca.vec(outs[name])
    Vd = ca.jtimes(V, x, ode_f.call([t, x, p])[0]) + ca.jacobian(V, t)
    return ca.Function("plain", [t, x, p], [V, Vd, *(outs[e] for e in extra)])


def test_one_function_for_both_lyapunov_functions_gives_the_same_bits(loop, monkeypatch):
    """The fast path evaluates V1, V̇1, V2, V̇2, χ as one Function (one right-hand side for
    both V̇): the very numbers of a separate Function per V, bit for bit."""
    monkeypatch.setattr(L, "COMPILE_FROM_USE", 10**9)  # SX virtual machine
    L.clear_cache()
    _, _, cl, grid, X = loop
    entry = L.fast_functions(cl)
    fast = L.evaluate_p(entry, "V1", grid, X, cl.p0) + L.evaluate_p(entry, "V2", grid, X, cl.p0)
    plain = []
    for f in (_separate_p(cl, "V1"), _separate_p(cl, "V2", ("chi",))):
        K = len(grid)
        args = [ca.DM(grid.reshape(1, -1)), ca.DM(np.asarray(X).T), ca.DM(cl.p0)]
        plain += L._blocks(f, f.map("m", "serial", K, [2], []).call(args), K)
    assert len(fast) == len(plain) == 5
    for got, want in zip(fast, plain, strict=True):
        assert got.shape == want.shape
        assert got.tobytes() == np.ascontiguousarray(want).tobytes()
    assert entry.functions["V"].n_instructions() < sum(
        _separate_p(cl, *a).n_instructions() for a in (("V1",), ("V2", ("chi",)))
    )


@pytest.fixture(scope="module")
def fault_runs(tmp_path_factory):
    """Two samples of studies/faults.toml (one structure), simulated by the native library."""
    from generated import api
    from sweep.sampler import make_sample
    from sweep.study import load_study

    out = tmp_path_factory.mktemp("faults")
    study = load_study(Path(__file__).resolve().parents[1] / "studies" / "faults.toml")
    runs = []
    for k in (1, 2):
        sc = make_sample(study, k).scenario
        gains, _ = api.ensure_gains(sc, out)
        codegen = api.resolve_codegen(sc.N)
        built = api.build(sc, gains, sc.integration.method, codegen)
        traj = api.simulate(built, sc, api.integrator_settings(sc, sc.integration.method, codegen))
        traj.raise_if_incomplete()
        runs.append((sc, gains, built.closed_loop, traj.t, traj.x))
    return runs


@pytest.mark.parametrize("compile_from", [10**9, 1], ids=["sx", "compiled"])
def test_fast_path_equals_mx_path_on_fault_samples(fault_runs, compile_from, monkeypatch):
    """Both samples go through the Functions built for the first, each with its own p."""
    monkeypatch.setattr(L, "COMPILE_FROM_USE", compile_from)
    L.clear_cache()
    (*_, cl1, _, _), (*_, cl2, _, _) = fault_runs
    assert not np.array_equal(cl1.p0, cl2.p0)  # different faults: different numbers in p
    for sc, gains, cl, t, X in fault_runs:
        _assert_checks_equal(sc, gains, cl, t, X)
    entries = {id(L.fast_functions(run[2])) for run in fault_runs}
    assert len(entries) == 1  # one structure, one set of Functions
    entry = L.fast_functions(fault_runs[0][2])
    assert entry.compiled == (compile_from == 1)
    assert all(f.is_a("SXFunction") != entry.compiled for f in entry.functions.values())


def test_closed_loop_of_a_second_sample_reuses_the_first_structure(fault_runs):
    """verify's closed loop for the second sample: its own numbers on the first's Functions."""
    from symbolic.closed_loop import build_closed_loop

    L.clear_cache()
    (sc1, g1, *_), (sc2, g2, _, t, X) = fault_runs
    first = L.closed_loop(sc1, g1)
    second = L.closed_loop(sc2, g2)
    assert second.parametric is first.parametric
    fresh = build_closed_loop(sc2, g2)
    np.testing.assert_array_equal(second.p0, fresh.p0)
    np.testing.assert_array_equal(second.x0, fresh.x0)
    k = len(t) // 2
    got = second.outputs(t[k], X[k])
    want = fresh.outputs(t[k], X[k])
    for a, b in zip(got, want, strict=True):
        _assert_same(np.asarray(a), np.asarray(b))
    # a build made elsewhere in the process (here: the fresh one) is what verify binds next
    assert L.closed_loop(sc1, g1).parametric is fresh.parametric


def test_another_runs_p_gives_other_values(fault_runs, monkeypatch):
    """The comparison above sees p: sample 2's states with sample 1's p differ from the MX path."""
    monkeypatch.setattr(L, "COMPILE_FROM_USE", 10**9)
    L.clear_cache()
    (*_, cl1, _, _), (sc2, _, cl2, t, X) = fault_runs
    entry = L.fast_functions(cl2)
    wrong = L.evaluate_p(entry, "V2", t, X, cl1.p0)[1][:, :, 0]
    right = L.evaluate_p(entry, "V2", t, X, cl2.p0)[1][:, :, 0]
    mx = np.array([c.lhs for c in check_theorem2(_mx_path(cl2), sc2, t, X)]).T
    _assert_same(right, mx)
    with pytest.raises(AssertionError):
        _assert_same(wrong, mx)
