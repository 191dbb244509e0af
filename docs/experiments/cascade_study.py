"""Study: the closed loop integrated follower by follower (method 'cascade', not kept).

Reproduces the numbers of docs/performance.md, section "Follower by follower". Run from
the commit that holds generated/cascade.py (see that section):

    python docs/experiments/cascade_study.py paper [rtol]      # N = 5 vs native
    FILT=1 python docs/experiments/cascade_study.py paper      # filtered derivatives
    python docs/experiments/cascade_study.py bench 50 5        # N = 50, 5 s horizon

``paper``: first checks that the per-follower block reproduces the whole closed loop's
right-hand side at a random state (exact upstream jets), then runs the cascade and the
native integrator and prints steps per follower and the deviation per state group.
"""

import dataclasses
import os
import sys
import time

import numpy as np

from generated import api, cascade
from generated.integrate import IntegratorSettings
from symbolic.cascade import build_cascade
from symbolic.closed_loop import build_closed_loop


def block_check(cl, cas) -> float:
    lay = cas.layout
    m, na, n = lay.m, lay.agent_size, cas.n
    rng = np.random.default_rng(0)
    x = cl.x0 + rng.normal(scale=0.3, size=cl.x0.size)
    t = 0.7
    xd = np.array(cl.ode(t, x)).ravel()
    fv = np.array(cas.faults(t)).ravel()
    jets, err = {}, 0.0
    for i in cas.order:
        nb = np.zeros(3 * n)
        for k in range(cas.upstream_ptr[i], cas.upstream_ptr[i + 1]):
            nb += cas.upstream_weight[k] * jets[cas.upstream_idx[k]][: 3 * n]
        xb = np.concatenate([x[:m], x[m + i * na : m + (i + 1) * na]])
        out = cas.block(t, xb, nb, cas.coupling[i], cas.params[:, i], fv[cas.fault_index[i]])
        jets[i] = np.array(out[1]).ravel()
        ref = np.concatenate([xd[:m], xd[m + i * na : m + (i + 1) * na]])
        err = max(err, float(np.max(np.abs(np.array(out[0]).ravel() - ref) / (1 + np.abs(ref)))))
    return err


def paper(rtol: float) -> None:
    from symbolic.scenario import load_scenario
    from synthesis.gains import load_gains

    sc = load_scenario("scenarios/paper.toml")
    if os.environ.get("FILT"):
        sc = dataclasses.replace(
            sc, options=dataclasses.replace(sc.options, derivatives="filtered")
        )
    g = load_gains("out/paper/gains.json")
    cl = build_closed_loop(sc, g)
    cas = build_cascade(sc, g)
    print("block vs whole closed loop, max rel difference:", block_check(cl, cas))
    lib = cascade.build(cas)
    t_out = api.output_grid(sc.integration.horizon, sc.integration.output_step)
    s = IntegratorSettings(method="native", rtol=rtol, atol=rtol * 1e-2, max_steps=100000)
    bps = sc.breakpoints()
    tr = cascade.run(lib.path, cas, cl.x0, t_out, s, breakpoints=bps)
    built = api.build(sc, g, method="native", closed_loop=cl)
    ref = api.integrate_built(built, cl.x0, t_out, s, bps)
    print(
        "cascade:",
        tr.complete,
        tr.message,
        f"{tr.stats['wall_seconds']:.3f} s,",
        tr.stats["steps"],
        "steps; per follower",
        tr.stats["agent_steps"],
    )
    print(
        "native: ", ref.complete, f"{ref.stats['wall_seconds']:.3f} s,", ref.stats["steps"], "steps"
    )
    k = min(len(tr.t), len(ref.t))
    D = np.abs(tr.x[:k] - ref.x[:k]) / (np.abs(ref.x[:k]).max(axis=0) + 1e-12)
    lay = cas.layout
    print("deviation / column max: leader", f"{D[:, : lay.m].max():.2e}")
    for i in range(lay.N):
        print(f"  follower {i + 1} (depth {cas.depth[i]}):", {
            nm: f"{D[:, lay.slices[(nm, i)]].max():.1e}"
            for nm in ("mu", "eta", "phi", "p", "q", "thetahat", "ghat")})  # fmt: skip


def bench(N: int, horizon: float) -> None:
    from generated.bench import bench_gains, bench_scenario

    sc = bench_scenario(N, horizon=horizon)
    g = bench_gains(sc)[0]
    cas = build_cascade(sc, g)
    lib = cascade.build(cas)
    cl = build_closed_loop(sc, g)
    t_out = api.output_grid(sc.integration.horizon, sc.integration.output_step)
    s = IntegratorSettings(method="native", rtol=1e-6, atol=1e-8, max_steps=100000)
    t0 = time.perf_counter()
    tr = cascade.run(lib.path, cas, cl.x0, t_out, s, breakpoints=sc.breakpoints())
    st = np.array(tr.stats["agent_steps"])
    print(f"N = {N}, {horizon} s: complete {tr.complete}, {time.perf_counter() - t0:.2f} s, "
          f"{st.sum()} steps; per follower median {np.median(st):.0f}, "
          f"min {st.min()}, max {st.max()}")  # fmt: skip
    for d in range(cas.depth.max() + 1):
        sel = cas.depth == d
        print(f"  depth {d}: {sel.sum()} followers, median {np.median(st[sel]):.0f} steps")


if __name__ == "__main__":
    if sys.argv[1] == "paper":
        paper(float(sys.argv[2]) if len(sys.argv) > 2 else 1e-6)
    else:
        bench(int(sys.argv[2]), float(sys.argv[3]))
