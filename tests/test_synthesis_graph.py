"""Lemma 3 on random graphs (hypothesis), signed-graph gauge, and a 1,000-follower graph."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla
from helpers import ROOT
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.errors import SynthesisError
from core.graph import check_network, find_gauge
from core.scenario import Graph, load_scenario
from synthesis import certify, synthesize
from synthesis.lemma3 import best_diagonal_z, lemma3, lemma3_z, w_of


@st.composite
def spanning_tree_graphs(draw, max_n: int = 9):
    """A random weighted digraph containing a spanning tree rooted at the leader."""
    N = draw(st.integers(1, max_n))
    perm = draw(st.permutations(range(N)))
    A = np.zeros((N, N))
    pin = np.zeros(N)
    w = st.floats(0.1, 5.0)
    pin[perm[0]] = draw(w)
    for k in range(1, N):  # each follower hears an earlier one in a random order
        parent = perm[draw(st.integers(0, k - 1))]
        A[perm[k], parent] = draw(w)
    extra = draw(
        st.lists(st.tuples(st.integers(0, N - 1), st.integers(0, N - 1), w), max_size=2 * N)
    )
    for i, j, a in extra:
        if i != j:
            A[i, j] = a
    for i in draw(st.lists(st.integers(0, N - 1), max_size=N)):
        pin[i] = max(pin[i], 0.5)
    return A, pin


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spanning_tree_graphs())
def test_lemma3_on_random_spanning_tree_graphs(graph):
    A, pin = graph
    net = check_network(A, pin)
    Lb = net.L_bar.toarray()
    z = lemma3_z(net.L_bar)
    # independent: dense solve of L̄ᵀz = 1
    np.testing.assert_allclose(z, np.linalg.solve(Lb.T, np.ones(len(pin))), rtol=1e-9)
    assert z.min() > 0
    Z = np.diag(z)
    S = Lb.T @ Z + Z @ Lb
    assert np.linalg.eigvalsh(S)[0] > 0
    w = w_of(Lb, z)
    # second implementation: generalised symmetric eigenproblem S v = λ Z v
    assert w == pytest.approx(sla.eigh(S, Z, eigvals_only=True)[0], rel=1e-9, abs=1e-12)
    assert w > 0
    assert np.linalg.eigvalsh(S - w * Z)[0] >= -1e-9 * max(1.0, np.abs(S).max())
    # no diagonal Z can beat 2·min Re λ(L̄)
    assert w <= 2 * np.linalg.eigvals(Lb).real.min() + 1e-9


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spanning_tree_graphs(max_n=6))
def test_best_z_is_admissible_and_not_worse(graph):
    A, pin = graph
    net = check_network(A, pin)
    r = lemma3(net.L_bar)
    names = {v.name: v for v in r.variants}
    best, paper = names["best"], names["lemma3"]
    Lb = net.L_bar.toarray()
    Z = np.diag(best.z)
    assert best.z.min() > 0
    assert np.linalg.eigvalsh(Lb.T @ Z + Z @ Lb - best.w * Z)[0] >= -1e-8 * np.abs(Z).max()
    assert r.used.w == max(best.w, paper.w)
    # when the paper's Z fits into the box I ⪯ Z ⪯ 100·I, bisection starts from it
    if paper.z.max() / paper.z.min() <= 100:
        assert best.w >= paper.w * (1 - 1e-6)


def test_best_z_tridiagonal_path_analytic():
    # path leader -> 1 -> 2 with unit weights: L̄ = [[1, 0], [-1, 1]], eigenvalues 1, 1.
    # With Z = diag(z1, z2), S - wZ ⪰ 0 gives (2-w)² z1 z2 ≥ z2², so w = 2 - sqrt(z2/z1);
    # the box I ⪯ Z ⪯ 100·I gives the optimum z2/z1 = 1/100, w = 1.9.
    Lb = np.array([[1.0, 0.0], [-1.0, 1.0]])
    z, w, _ = best_diagonal_z(Lb, 0.0)
    assert w == pytest.approx(1.9, rel=2e-4)
    assert w_of(Lb, np.array([5.0, 1.0])) == pytest.approx(2 - np.sqrt(1 / 5), rel=1e-12)
    assert w_of(Lb, lemma3_z(Lb)) == pytest.approx(2 - np.sqrt(1 / 2), rel=1e-12)  # z = (2, 1)


# --------------------------------------------------------------------------- signed graphs
@settings(max_examples=40, deadline=None)
@given(spanning_tree_graphs(), st.data())
def test_gauge_found_for_structurally_balanced_graphs(graph, data):
    A, pin = graph
    N = len(pin)
    h = np.array(data.draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=N, max_size=N)))
    h[pin > 0] = 1.0  # pinned followers in the leader's camp (the opposite is refused)
    As = np.diag(h) @ A @ np.diag(h)  # balanced by construction
    hf = find_gauge(As, pin)
    assert set(np.unique(hf)) <= {-1.0, 1.0}
    # h_i h_j = sign(a_ij) on every edge
    i, j = np.nonzero(As)
    np.testing.assert_array_equal(hf[i] * hf[j], np.sign(As[i, j]))
    net = check_network(As, pin)
    # L̄ of the signed graph equals the Laplacian of |A| (Remark 2)
    Lab = np.diag(np.abs(A).sum(1) + pin) - np.abs(A)
    np.testing.assert_allclose(net.L_bar.toarray(), Lab, atol=0)


def test_unbalanced_cycle_named():
    # 1 -> 2 -> 3 -> 1 (as edges a_21, a_32, a_13) with one negative edge
    A = np.zeros((3, 3))
    A[1, 0], A[2, 1], A[0, 2] = 1.0, -1.0, 1.0
    with pytest.raises(
        SynthesisError,
        match=r"not structurally balanced: cycle [123] - [123] - [123] - [123] .* has 1 negative",
    ):
        check_network(A, np.array([1.0, 0.0, 0.0]))
    # a two-cycle with opposite signs
    B = np.zeros((2, 2))
    B[0, 1], B[1, 0] = 1.0, -1.0
    with pytest.raises(SynthesisError, match=r"cycle 1 -> 2 -> 1 has one negative edge"):
        check_network(B, np.array([1.0, 0.0]))


def test_signed_paper_graph_synthesises_with_gauge():
    sc = load_scenario(ROOT / "scenarios" / "paper-synth.toml")
    h = np.array([1.0, -1.0, 1.0, -1.0, -1.0])
    As = np.diag(h) @ np.array(sc.graph.adjacency) @ np.diag(h)
    g = synthesize(replace(sc, graph=Graph(adjacency=As, pinning=sc.graph.pinning)))
    np.testing.assert_array_equal(np.diag(g.H), h)  # follower 1 is pinned: h_1 = +1
    assert g.info["signed_graph"] and g.certificate["passed"]
    g0 = synthesize(sc)
    assert g.w == pytest.approx(g0.w, rel=1e-9)  # the gauge does not change L̄


# --------------------------------------------------------------------------- scale
def test_thousand_followers_sparse():
    sc = load_scenario(ROOT / "scenarios" / "paper-synth.toml")
    N = 1000
    rng = np.random.default_rng(3)
    A = np.zeros((N, N))
    for i in range(1, N):
        A[i, rng.integers(0, i)] = 1.0
        j = int(rng.integers(0, N))
        if j != i:
            A[i, j] = 0.5
    pin = np.zeros(N)
    pin[:3] = 1.0
    g = synthesize(replace(sc, graph=Graph(adjacency=A, pinning=pin)))
    assert g.info["lemma3"]["used"] == "lemma3" and "N = 1000" in g.info["lemma3"]["skipped"]
    # dense second implementation of w
    z = np.diag(g.Z)
    Lb = g.L_bar
    S = Lb.T * z + z[:, None] * Lb
    w_dense = sla.eigh(S, np.diag(z), eigvals_only=True, subset_by_index=[0, 0])[0]
    assert g.w == pytest.approx(w_dense, rel=1e-7)
    np.testing.assert_allclose(Lb.T @ z, 1.0, rtol=1e-9)
    assert certify(g).passed
