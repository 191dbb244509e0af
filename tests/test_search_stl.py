"""The STL robustness evaluator of search/stl.py against hand-computed values and against
RTAMT's discrete-time monitor (a second implementation), and its parse errors."""

from __future__ import annotations

import numpy as np
import pytest

from search.stl import FormulaError, parse, robustness, trace

T = np.round(np.arange(0, 2001) * 0.01, 10)  # 0 .. 20 s, 0.01 s
SIGNALS = {"dev", "u"}


def test_hand_computed_values():
    dev = 2 * np.exp(-T / 2)
    u = np.sin(T)
    v = {"dev": dev, "u": u}
    # always[10,20](dev <= 0.5): 0.5 - max over [10, 20] of dev = 0.5 - 2 e^-5
    assert robustness(parse("always[10, 20](dev <= 0.5)", SIGNALS), T, v) == pytest.approx(
        0.5 - 2 * np.exp(-5.0), abs=1e-12
    )
    # eventually[0,5](u >= 1): max of sin over [0, 5] sampled at 0.01 s, minus 1
    expect = np.sin(T[T <= 5 + 1e-9]).max() - 1.0
    assert robustness(parse("eventually[0, 5](u >= 1)", SIGNALS), T, v) == pytest.approx(expect)
    # and / or / not / a constant on the left
    f = parse("not (dev > 3) and (0.2 >= u or always[0, 1](dev <= 2.5))", SIGNALS)
    a = 3 - dev[0]  # not(dev > 3) at t = 0: -(dev - 3)
    b = max(0.2 - u[0], 2.5 - dev[T <= 1 + 1e-9].max())
    assert robustness(f, T, v) == pytest.approx(min(a, b))
    # a violated requirement is negative
    assert robustness(parse("always[0, 20](dev <= 1)", SIGNALS), T, v) == pytest.approx(-1.0)


def test_nested_windows_match_a_direct_loop():
    rng = np.random.default_rng(3)
    x = rng.normal(size=300)
    t = np.arange(300) * 0.1
    node = parse("always[0, 2](eventually[0.5, 1.3](dev <= 0.1))", {"dev"})
    got = trace(node, t, {"dev": x})
    inner = np.array(
        [max(0.1 - x[(t >= s + 0.5 - 1e-9) & (t <= s + 1.3 + 1e-9)], default=-np.inf) for s in t]
    )
    outer = np.array([min(inner[(t >= s - 1e-9) & (t <= s + 2 + 1e-9)]) for s in t])
    assert np.allclose(got, outer)


@pytest.mark.parametrize(
    "formula",
    [
        "always[10, 20](dev <= 0.5)",
        "eventually[0, 5](u >= 0.9) and always[2, 8](dev < 1.2)",
        "always[0, 10](dev <= 1.0 or eventually[0, 3](u > 0.5))",
        "not eventually[1, 4](u >= 0.7)",
    ],
)
def test_against_rtamt(formula):
    rtamt = pytest.importorskip("rtamt")
    rng = np.random.default_rng(5)
    t = np.round(np.arange(0, 1501) * 0.01, 10)
    dev = 2 * np.exp(-t / 3) + 0.05 * rng.normal(size=t.size)
    u = np.sin(1.3 * t) + 0.1 * rng.normal(size=t.size)
    spec = rtamt.StlDiscreteTimeSpecification()
    spec.declare_var("dev", "float")
    spec.declare_var("u", "float")
    spec.set_sampling_period(10, "ms", 0.1)
    spec.spec = formula
    spec.parse()
    theirs = spec.evaluate({"time": t.tolist(), "dev": dev.tolist(), "u": u.tolist()})[0][1]
    ours = robustness(parse(formula, SIGNALS), t, {"dev": dev, "u": u})
    assert ours == pytest.approx(theirs, abs=1e-12)


@pytest.mark.parametrize(
    ("formula", "words"),
    [
        ("always[10, 20](devx <= 0.5)", "unknown signal 'devx'"),
        ("always[10, 20](dev <= ", "expected"),
        ("always[20, 10](dev <= 1)", "0 <= a <= b"),
        ("dev <= u", "compare one signal with a number"),
        ("dev <= 1 dev", "after a complete formula"),
        ("", "empty formula"),
    ],
)
def test_parse_errors_name_the_problem(formula, words):
    with pytest.raises(FormulaError) as exc:
        parse(formula, SIGNALS)
    assert words in str(exc.value) and "\n" not in str(exc.value)
