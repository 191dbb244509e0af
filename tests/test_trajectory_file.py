"""The frame's outputs evaluated as SX (generated/trajectory_file.py) against the MX
Function they are expanded from: the same numbers, bit for bit."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from core.scenario import load_scenario
from generated.csource import expanded
from generated.trajectory_file import evaluate_outputs
from symbolic.closed_loop import build_closed_loop
from verify.reference import hand_gains


def test_outputs_expanded_equal_the_mx_function_bit_for_bit():
    sc = load_scenario("scenarios/paper.toml")
    cl = build_closed_loop(sc, hand_gains(sc))
    f = cl.parametric.outputs
    assert f.is_a("MXFunction")  # what the per-agent engine's frame evaluates
    rng = np.random.default_rng(3)
    K = 7
    t = np.sort(rng.uniform(0.0, 20.0, K))
    x = cl.x0 + rng.normal(size=(K, cl.layout.nx))  # away from x(0): every term non-zero
    for i in range(cl.layout.N):  # φ_i > 0 and ĝ_i in its bounds, as the run keeps them
        x[:, cl.layout.slices[("phi", i)]] = rng.uniform(0.01, 1.0, (K, 1))
        x[:, cl.layout.slices[("ghat", i)]] = rng.uniform(1.0, 2.0, (K, 1))
    built = SimpleNamespace(outputs_p=f, outputs=None, p=cl.p0)
    got = evaluate_outputs(built, SimpleNamespace(t=t, x=x))
    assert expanded(f).is_a("SXFunction")  # the path under test: expanded, then mapped
    # the MX Function mapped over the times, as the frame evaluated it before
    old = f.map(K, [nm == "p" for nm in f.name_in()], [False] * f.n_out())
    want = old(t.reshape(1, -1), x.T, cl.p0)
    for j, nm in enumerate(f.name_out()):
        r, c = f.size_out(j)
        w = np.asarray(want[j]).reshape(r, K, c).transpose(1, 0, 2)  # r x (c K), by time
        assert np.isfinite(w).all(), nm
        np.testing.assert_array_equal(got[nm], w, err_msg=nm)
