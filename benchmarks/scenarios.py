"""The benchmark's scenarios: the paper's at N = 5, a random acyclic graph of its followers above.

Imported by the benchmarks and by the tests (no command line here): :func:`bench_scenario`
builds N followers from ``scenarios/paper.toml`` (the paper's follower model and faults,
cycled; offsets on a circle of radius 4; p_i(0) = b_i0 + noise) on :func:`random_graph`,
in which every follower hears its spanning-tree parent and up to two more earlier
followers (fixed seed), with one follower in a hundred pinned to the leader;
:func:`bench_gains` gives their gains.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.catalogue import BenchError, integration_method, ours_method

BENCH_SEED = 20260121
PAPER = Path(__file__).resolve().parent.parent / "scenarios" / "paper.toml"


def random_graph(N: int, seed: int = BENCH_SEED) -> tuple[np.ndarray, np.ndarray]:
    """A random sparse acyclic graph with a spanning tree rooted at the leader.

    Follower 0 is pinned; follower i ≥ 1 hears a random parent j < i (the spanning
    tree) and up to two more random earlier followers (about 3 neighbours each);
    ``max(1, N // 100)`` followers are pinned (follower 0 among them). Acyclic, so L + B is triangular with
    eigenvalues ≥ 1 (the observer network is stable for any N).

    Parameters
    ----------
    N : int
        Number of followers (>= 1).
    seed : int
        Random seed.

    Returns
    -------
    (adjacency, pinning)
        ``adjacency[i, j] = 1`` when follower i hears follower j.
    """
    if N < 1:
        raise BenchError(f"N: {N} must be >= 1")
    rng = np.random.default_rng(seed)
    A = np.zeros((N, N))
    pin = np.zeros(N)
    pin[0] = 1.0
    for i in range(1, N):
        A[i, int(rng.integers(0, i))] = 1.0
        extra = rng.choice(i, size=min(2, i), replace=False)
        A[i, extra] = 1.0
    k = max(1, N // 100)
    if k > 1:  # more pinned followers besides follower 0
        pin[1 + rng.choice(N - 1, k - 1, replace=False)] = 1.0
    return A, pin


def bench_scenario(N: int, seed: int = BENCH_SEED, horizon: float | None = None):
    """The benchmark scenario with N followers (N = 5: the paper's own scenario).

    Parameters
    ----------
    N : int
    seed : int
        Graph and initial-position seed.
    horizon : float, optional
        Override of ``integration.horizon`` (default: the paper's 20 s).

    Returns
    -------
    Scenario
        With ``integration.method`` that of :func:`ours_method` (``native``).
    """
    from core.scenario import Graph, load_scenario

    base = load_scenario(PAPER)
    if N == base.N:
        sc = base
    else:
        A, pin = random_graph(N, seed)
        rng = np.random.default_rng(seed + 1)
        followers = []
        for i in range(N):
            src = base.followers[i % base.N]
            ang = 2.0 * math.pi * i / N
            b0 = np.array([4.0 * math.cos(ang), 4.0 * math.sin(ang)])
            p0 = b0 + rng.normal(scale=0.5, size=2)
            followers.append(dataclasses.replace(src, b0=_frozen(b0), p0=_frozen(p0)))

        def rep(a: Any) -> np.ndarray:  # first agent's value for every agent
            return _frozen(np.repeat(np.asarray(a)[:1], N, axis=0))

        o, c, ini = base.observer, base.controller, base.initial
        sc = dataclasses.replace(
            base,
            name=f"bench-N{N}",
            path=f"{PAPER} (benchmarks.bench: N = {N}, seed {seed})",
            sha256=f"bench-N{N}-seed{seed}-{base.sha256}",
            description=f"benchmark: {N} followers on a random acyclic graph (seed {seed})",
            graph=Graph(adjacency=_frozen(A), pinning=_frozen(pin)),
            followers=tuple(followers),
            observer=dataclasses.replace(
                o, alpha1=rep(o.alpha1), alpha1_bar=rep(o.alpha1_bar), phi0=rep(o.phi0)
            ),
            controller=dataclasses.replace(
                c,
                **{
                    k: rep(getattr(c, k))
                    for k in ("Lambda", "k1", "k2", "gamma", "sigma", "ghat_ref")
                },
            ),
            initial=dataclasses.replace(
                ini,
                eta=rep(ini.eta),
                mu=rep(ini.mu),
                theta_hat=rep(ini.theta_hat),
                ghat=rep(ini.ghat),
            ),
        )
    # the method make sim would use at this N
    ig = dataclasses.replace(sc.integration, method=integration_method(ours_method(N)))
    if horizon is not None:
        ig = dataclasses.replace(ig, horizon=float(horizon))
    return dataclasses.replace(sc, integration=ig)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def bench_gains(sc):
    """Gains for the benchmark: :func:`synthesis.synthesize` (uncertified warnings allowed).

    Parameters
    ----------
    sc : Scenario
        A :func:`bench_scenario`.

    Returns
    -------
    (Gains, str)
        The gains and where they came from.
    """
    from synthesis import synthesize

    g = synthesize(sc)
    cert = g.certificate or {}
    tag = "synthesize" + ("" if cert.get("passed", True) else " (certificate warnings)")
    return g, tag
