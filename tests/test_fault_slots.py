"""The generic fault form (``options.fault_slots``, docs/scenario-format.md 'Faults').

Independent truth: the closed forms of the documented faults written here with numpy
(abrupt 30 % at 0.4 s on g = 0.95 is 0.95 · 0.7 from 0.4 s on; a clipped linear ramp; the
pulse train [onset + kP, onset + kP + duty P)), the type-specific trees of
:mod:`core.faults` (a second implementation, checked against the same closed forms by
tests/test_faults.py), the definition of right-continuity (the new value at a switching
time, the old one at the float just before it) and the closed loop integrated with the
type-specific trees.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib

import casadi as ca
import numpy as np
import pytest
from helpers import ROOT, SCENARIOS

from core.errors import ScenarioError
from core.expression_tree import Node, Num, Transformer, visit
from core.expressions import Expr
from core.faults import Fault, Slot, fault_times, slot_activation
from core.scenario import Scenario, load_scenario, scenario_from_dict

HORIZON = 10.0
BASE = f"""
[leader]
A0 = [[0, 1], [0, 0]]
B0 = [[0], [1]]
C0 = [[1, 0], [0, 1]]
u0 = ["cos(t)"]
alpha = 1
[graph]
adjacency = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
pinning = [1, 0, 0]
[integration]
horizon = {HORIZON}
"""
FOLLOWER = """
[[followers]]
model = "point_mass_2d"
p0 = [0, 0]
b0 = [1, 0]
g = 0.9
f = ["sin(t)", "2"]
"""


def _fault(**keys) -> str:
    body = "".join(
        f"{k} = {v!r}\n" if not isinstance(v, str) else f'{k} = "{v}"\n' for k, v in keys.items()
    )
    return "[[followers.faults]]\n" + body


def _load(tmp_path, faults: list[list[dict]], slots: int | str | None) -> Scenario:
    """Three followers (g = 0.9, f = (sin t, 2)) with ``faults[i]`` on follower i + 1."""
    text = BASE + "".join(FOLLOWER + "".join(_fault(**fa) for fa in fl) for fl in faults)
    if slots is not None:
        text += f"[options]\nfault_slots = {slots!r}\n".replace("'", '"')
    path = tmp_path / f"slots-{slots}.toml"
    path.write_text(text)
    return load_scenario(path)


# --------------------------------------------------------------------------- closed forms
def _step(ts: np.ndarray, t0: float) -> np.ndarray:
    return np.where(ts >= t0, 1.0, 0.0)


def _pulses(ts: np.ndarray, onset: float, period: float, duty: float) -> np.ndarray:
    """1 on the pulses [onset + k P, onset + k P + duty P), else 0."""
    on = np.zeros(ts.shape, dtype=bool)
    k = 0
    while onset + k * period < HORIZON:
        start = onset + k * period
        on |= (ts >= start) & (ts < start + duty * period)
        k += 1
    return on.astype(float)


def _loss(ts: np.ndarray, fa: dict) -> np.ndarray:
    """The fraction of effectiveness a health fault removes at ``ts`` (0 for a bias)."""
    kind, t0 = fa["type"], fa["onset"]
    if kind == "abrupt":
        return fa["severity"] * _step(ts, t0)
    if kind == "ramp":
        return fa["severity"] * np.clip((ts - t0) / fa["duration"], 0.0, 1.0)
    if kind == "intermittent":
        return fa["severity"] * _pulses(ts, t0, fa["period"], fa["duty"])
    return np.zeros_like(ts)


def _truth(ts: np.ndarray, faults: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """g, f_1, f_2 of one follower by the documented rule: product of factors, sum of biases."""
    g = 0.9 * np.prod([1.0 - _loss(ts, fa) for fa in faults] or [np.ones_like(ts)], axis=0)
    f = [np.sin(ts), np.full_like(ts, 2.0)]
    for fa in faults:
        if fa["type"] == "bias":
            f = [f[r] + fa["amplitude"][r] * _step(ts, fa["onset"]) for r in range(2)]
    return g, f[0], f[1]


def _nominal(fa: dict) -> list[float]:
    """The documented switching times of a fault (onset + k period (+ duty period))."""
    if fa["type"] == "ramp":
        return [fa["onset"], fa["onset"] + fa["duration"]]
    if fa["type"] != "intermittent":
        return [fa["onset"]]
    out, k = [], 0
    while fa["onset"] + k * fa["period"] < HORIZON:
        on = fa["onset"] + k * fa["period"]
        out += [on, on + fa["duty"] * fa["period"]]
        k += 1
    return out


def _grid(switches: list[float]) -> np.ndarray:
    """A dense grid plus points 1e-9 s around each switch, none within 1e-12 s of one.

    Exactly at a switch the generic form may differ from the closed form by rounding of
    t − onset (a few units in the last place); :func:`test_right_continuous_at_each_switch`
    covers those times.
    """
    sw = np.array(switches, dtype=float)
    ts = np.linspace(0.0, HORIZON, 20001)
    ts = np.concatenate([ts, sw - 1e-9, sw + 1e-9])
    ts = ts[(ts >= 0.0) & (ts <= HORIZON)]
    if sw.size:
        ts = ts[np.all(np.abs(ts[:, None] - sw[None, :]) > 1e-12, axis=1)]
    return np.unique(ts)


def _values(e: Expr, ts: np.ndarray) -> np.ndarray:
    return np.array(np.broadcast_to(e.numpy(ts), ts.shape), dtype=float)


def _casadi(e: Expr, ts: np.ndarray, parametric: bool) -> np.ndarray:
    """``e`` on ``ts`` through CasADi; ``parametric``: its literals are inputs (no folding)."""
    t = ca.SX.sym("t")
    if not parametric:
        fun = ca.Function("e", [t], [ca.SX(e.casadi(t))])
        return np.array(fun(ts.reshape(1, -1))).ravel()
    lits = ca.SX.sym("p", len(e.literals()))
    fun = ca.Function("e", [t, lits], [ca.SX(e.casadi(t, lits))])
    return np.array(fun.map(ts.size)(ts.reshape(1, -1), np.array(e.literals()))).ravel()


class _Erased(Transformer):
    """The tree with every number erased (written 0): what the compiled code depends on."""

    def num(self, node: Num) -> Node:
        return Num(0.0)


def _shape(node: Node) -> Node:
    """The node with every number erased: what the compiled code depends on."""
    return visit(node, _Erased())


# --------------------------------------------------------------------------- each type
ONE = {
    "abrupt": {"type": "abrupt", "onset": 3.5, "severity": 0.4},
    "ramp": {"type": "ramp", "onset": 2.0, "duration": 4.0, "severity": 0.5},
    "intermittent": {
        "type": "intermittent",
        "onset": 1.3,
        "period": 0.7,
        "duty": 0.3,
        "severity": 0.3,
    },
    "bias": {"type": "bias", "onset": 4.1, "amplitude": [0.5, -2.0]},
}


@pytest.mark.parametrize("kind", list(ONE))
@pytest.mark.parametrize(("who", "slots"), [(0, 1), (2, 3)])
def test_generic_form_equals_each_fault_type(tmp_path, kind, who, slots):
    fa = ONE[kind]
    faults = [[fa] if i == who else [] for i in range(3)]
    generic = _load(tmp_path, faults, slots)
    specific = _load(tmp_path, faults, None)
    ts = _grid(_nominal(fa))
    for i in range(3):
        truth = _truth(ts, faults[i])
        got = (generic.followers[i].g.expr, *generic.followers[i].f)
        ref = (specific.followers[i].g.expr, *specific.followers[i].f)
        for e, r, want in zip(got, ref, truth, strict=True):
            np.testing.assert_allclose(_values(e, ts), want, rtol=1e-14, atol=1e-14)
            # empty slots multiply by exactly 1 and add exactly 0
            np.testing.assert_array_equal(_values(e, ts), _values(r, ts))
        assert generic.followers[i].g.minimum == specific.followers[i].g.minimum
        np.testing.assert_array_equal(generic.followers[i].d, specific.followers[i].d)


def test_abrupt_30_percent_at_0_4_s_in_the_example(tmp_path):
    """faults-example.toml's follower 1: g = 0.95 before 0.4 s, 0.95 · 0.7 from 0.4 s on."""
    sc = _example(tmp_path, slots=2)
    ts = np.array([0.0, 0.2, np.nextafter(0.4, 0.0), 0.4, 0.41, 2.0, 5.0])
    want = np.where(ts >= 0.4, 0.95 * 0.7, 0.95)
    np.testing.assert_allclose(_values(sc.followers[0].g.expr, ts), want, rtol=1e-15, atol=0)


def test_several_faults_on_several_followers(tmp_path):
    first = [
        {"type": "abrupt", "onset": 2.0, "severity": 0.3},
        {"type": "ramp", "onset": 4.0, "duration": 2.0, "severity": 0.2},
        {"type": "intermittent", "onset": 5.0, "period": 3.0, "duty": 0.5, "severity": 0.1},
        {"type": "bias", "onset": 1.0, "amplitude": [1.0, 2.0]},
        {"type": "bias", "onset": 3.0, "amplitude": [-0.25, 0.5]},
    ]
    second = [{"type": "abrupt", "onset": 6.5, "severity": 0.5}]
    third = [
        {"type": "intermittent", "onset": 0.35, "period": 1.1, "duty": 0.45, "severity": 0.4},
        {"type": "bias", "onset": 2.7, "amplitude": [-1.5, 0.25]},
        {"type": "ramp", "onset": 0.9, "duration": 0.6, "severity": 0.15},
    ]
    faults = [first, second, third]
    generic = _load(tmp_path, faults, 5)
    specific = _load(tmp_path, faults, None)
    ts = _grid([t for fl in faults for fa in fl for t in _nominal(fa)])
    for i in range(3):
        truth = _truth(ts, faults[i])
        got = (generic.followers[i].g.expr, *generic.followers[i].f)
        ref = (specific.followers[i].g.expr, *specific.followers[i].f)
        for e, r, want in zip(got, ref, truth, strict=True):
            np.testing.assert_allclose(_values(e, ts), want, rtol=1e-14, atol=1e-14)
            np.testing.assert_allclose(_values(e, ts), _values(r, ts), rtol=1e-15, atol=1e-15)
        g_min = generic.followers[i].g.minimum
        assert g_min == pytest.approx(specific.followers[i].g.minimum, rel=1e-14)
    assert generic.followers[0].g.minimum == pytest.approx(0.9 * 0.7 * 0.8 * 0.9, rel=1e-12)


# --------------------------------------------------------------------------- switching times
def _side_values(e: Expr, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values at ``times`` and at the float just before each."""
    return _values(e, times), _values(e, np.nextafter(times, -np.inf))


def test_right_continuous_at_exact_switching_times(tmp_path):
    """With binary-exact numbers the generic form switches exactly at the documented times."""
    inter = {"type": "intermittent", "onset": 0.5, "period": 0.25, "duty": 0.5, "severity": 0.25}
    ramp = {"type": "ramp", "onset": 0.4, "duration": 1.5, "severity": 0.2}
    bias = {"type": "bias", "onset": 0.45, "amplitude": [1.0, -0.5]}
    sc = _load(
        tmp_path, [[inter], [{"type": "abrupt", "onset": 0.4, "severity": 0.3}], [bias, ramp]], 2
    )
    times = np.array([t for t in _nominal(inter) if t < HORIZON])
    at, before = _side_values(sc.followers[0].g.expr, times)
    new = np.tile([0.9 * 0.75, 0.9], times.size // 2)  # on at 0.5 + k/4, off at 0.625 + k/4
    np.testing.assert_array_equal(at, new)
    np.testing.assert_array_equal(before, np.where(new == 0.9, 0.9 * 0.75, 0.9))
    for backend in (False, True):
        np.testing.assert_array_equal(_casadi(sc.followers[0].g.expr, times, backend), new)
    at, before = _side_values(sc.followers[1].g.expr, np.array([0.4]))
    assert at[0] == 0.9 * 0.7 and before[0] == 0.9
    at, before = _side_values(sc.followers[2].f[0], np.array([0.45]))
    assert at[0] == np.sin(0.45) + 1.0 and before[0] == np.sin(np.nextafter(0.45, 0.0))
    assert set(times[(times > 0) & (times < HORIZON)]) <= set(sc.breakpoints())


def test_right_continuous_at_each_switch(tmp_path):
    """Switches of a non-binary intermittent fault: each is a breakpoint, the new value holds
    from it on and the old one up to the float before it; it is the documented time up to
    rounding of t − onset."""
    inter = ONE["intermittent"]
    sc = _load(tmp_path, [[inter], [], []], 1)
    nominal = np.array([t for t in _nominal(inter) if t < HORIZON])
    bps = np.array(sc.breakpoints())
    assert bps.size == nominal.size
    np.testing.assert_allclose(bps, nominal, rtol=4 * np.finfo(float).eps, atol=0)
    at, before = _side_values(sc.followers[0].g.expr, bps)
    on = np.tile([True, False], bps.size // 2)  # switching on at onset + k P, off duty P later
    np.testing.assert_array_equal(at, np.where(on, 0.9 * 0.7, 0.9))
    np.testing.assert_array_equal(before, np.where(on, 0.9, 0.9 * 0.7))
    for parametric in (False, True):
        e = sc.followers[0].g.expr
        np.testing.assert_array_equal(_casadi(e, bps, parametric), at)
        np.testing.assert_array_equal(_casadi(e, np.nextafter(bps, -np.inf), parametric), before)


def test_random_intermittent_switches_are_where_the_form_switches():
    """500 seeded random intermittent faults: every switching time of the generic form is
    right-continuous (new value at it, old value at the float before) and a few units in
    the last place from the documented onset + k P (+ duty P)."""
    rng = np.random.default_rng(2026)
    worst = 0
    for _ in range(500):
        fa = Fault(
            "intermittent",
            onset=rng.uniform(1.0, 15.0),
            severity=0.3,
            period=rng.uniform(0.5, 3.0),
            duty=rng.uniform(0.2, 0.8),
        )
        got = np.array(fault_times((fa,), 20.0, slots=1))
        nominal = np.array(fa.times(20.0))
        act = Expr("act", slot_activation(Slot.of(fa)))
        on = np.tile([1.0, 0.0], got.size // 2)
        np.testing.assert_array_equal(_values(act, got), on)
        np.testing.assert_array_equal(_values(act, np.nextafter(got, -np.inf)), 1.0 - on)
        worst = max(worst, int(np.abs(got.view(np.int64) - nominal.view(np.int64)).max()))
    assert worst <= 4


# --------------------------------------------------------------------------- structure
def test_shape_is_the_same_for_every_type_follower_and_padding(tmp_path):
    """Only the numbers differ: same node shape, template and literal count everywhere."""
    cases = [[[ONE[k]] if i == j else [] for i in range(3)] for k in ONE for j in range(3)]
    cases.append([[ONE["abrupt"], ONE["bias"]], [ONE["intermittent"]], []])
    cases.append([[], [ONE["ramp"], ONE["intermittent"]], [ONE["bias"], ONE["abrupt"]]])
    shapes = set()
    for n, faults in enumerate(cases):
        (tmp_path / str(n)).mkdir()
        sc = _load(tmp_path / str(n), faults, 2)
        for fo in sc.followers:
            for e in (fo.g.expr, *fo.f):
                shapes.add((_shape(e.node), e.template(), len(e.literals())))
    # one shape for g and one for each of the two f components (their base differs)
    assert len({s[0] for s in shapes}) == 3 and len(shapes) == 3
    # without slots the types are different code
    plain = [_load(tmp_path, [[ONE[k]], [], []], None) for k in ("abrupt", "intermittent")]
    assert plain[0].followers[0].g.expr.template() != plain[1].followers[0].g.expr.template()


def test_slot_count_is_structure(tmp_path):
    one = _load(tmp_path, [[ONE["abrupt"]], [], []], 1)
    two = _load(tmp_path, [[ONE["abrupt"]], [], []], 2)
    assert one.followers[0].g.expr.template() != two.followers[0].g.expr.template()
    zero = _load(tmp_path, [[], [], []], 0)
    assert zero.followers[0].g.expr.text == "0.9"  # no slot: g and f as written


# --------------------------------------------------------------------------- no NaN
EXTREME = [0.0, 5e-324, 1e-300, 0.3, 7.0, 1e300, -2.0]


def test_no_nan_for_any_slot_numbers():
    """Every combination of extreme numbers gives a finite act(t) in [0, 1], in both backends
    (CasADi with the numbers as inputs, so nothing is folded away)."""
    ts = np.array([0.0, 1e-300, 0.3, 1.0, 7.0, 1e6, 1e300])
    for onset in (0.0, 0.3, 1e6):
        for dur in EXTREME:
            for per in EXTREME:
                for duty in (0.0, 0.5, 1.0):
                    e = Expr("act", slot_activation(Slot(onset, 0.5, dur, per, duty, (1.0, -1.0))))
                    for v in (_values(e, ts), _casadi(e, ts, True)):
                        assert np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= 1)), (
                            onset,
                            dur,
                            per,
                            duty,
                        )


def test_slot_numbers_of_each_type():
    """A fault's slot: duration only for a ramp, period and duty only for an intermittent."""
    ramp = Slot.of(Fault("ramp", 1.0, severity=0.2, duration=3.0))
    assert (ramp.duration, ramp.period, ramp.duty, ramp.amplitude) == (3.0, 0.0, 0.0, ())
    bias = Slot.of(Fault("bias", 2.0, amplitude=(1.0, 2.0)))
    assert (bias.severity, bias.bias(1)) == (0.0, 2.0)
    assert Slot().bias(0) == 0.0


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("slots", "words"),
    [(-1, "negative"), (1.5, "not a whole number"), (101, "more than a follower"), ("two", "")],
)
def test_bad_slot_count_is_refused(tmp_path, slots, words):
    with pytest.raises(ScenarioError) as err:
        _load(tmp_path, [[], [], []], slots)
    msg = str(err.value)
    assert "options.fault_slots" in msg and words in msg and "\n" not in msg


def test_more_faults_than_slots_is_one_line_naming_follower_and_option(tmp_path):
    faults = [[ONE["abrupt"]], [ONE["ramp"], ONE["bias"]], []]
    with pytest.raises(ScenarioError) as err:
        _load(tmp_path, faults, 1)
    msg = str(err.value)
    assert "followers[2].faults" in msg and "options.fault_slots = 1" in msg, msg
    path = tmp_path / "slots-1.toml"
    res = subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2 and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "followers[2].faults" in lines[0] and "(expected " in lines[0]


# --------------------------------------------------------------------------- closed loop
def _example(tmp_path, slots: int | None, horizon: float | None = None) -> Scenario:
    path = SCENARIOS / "faults-example.toml"
    data = tomllib.loads(path.read_text())
    if slots is not None:
        data["options"]["fault_slots"] = slots
    if horizon is not None:
        data["integration"]["horizon"] = horizon
    return scenario_from_dict(data, path=path, sha256=f"slots-{slots}")


def _integrate(cl, grid: np.ndarray, breaks: tuple[float, ...], options: dict) -> np.ndarray:  # noqa: ANN001
    """States on ``grid``, CVODES restarted at each breakpoint (as the simulator does)."""
    dyn = cl.ode_dyn.expand()
    x = np.asarray(cl.x0, dtype=float).ravel()
    edges = [float(grid[0]), *[b for b in breaks if grid[0] < b < grid[-1]], float(grid[-1])]
    rows = [x]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        ts = np.unique(np.append(grid[(grid > a) & (grid <= b)], b))
        F = ca.integrator("F", "cvodes", dyn, a, ts, options)
        X = np.array(F(x0=x)["xf"])
        rows += [X[:, k] for k in range(ts.size) if np.any(grid == ts[k])]
        x = X[:, -1]
    return np.vstack(rows)


def test_closed_loop_with_slots_matches_the_type_specific_faults(tmp_path):
    """faults-example.toml over 0.5 s (all five fault onsets) with fault_slots = 2
    and without: the same trajectory to integration tolerance."""
    pytest.importorskip("generated.api")
    from generated import api
    from symbolic.closed_loop import build_closed_loop

    runs = []
    for slots in (None, 2):
        sc = _example(tmp_path, slots, horizon=0.5)
        gains, _ = api.ensure_gains(sc, tmp_path)
        cl = build_closed_loop(sc, gains)
        grid = np.linspace(0.0, 0.5, 51)
        opts = {"abstol": 1e-10, "reltol": 1e-9, "max_num_steps": 200000}
        runs.append((sc, _integrate(cl, grid, sc.breakpoints(), opts)))
    (plain, X0), (slotted, X1) = runs
    assert plain.breakpoints() == slotted.breakpoints() == (0.2, 0.25, 0.3, 0.4, 0.45)
    scale = np.maximum(np.abs(X0).max(axis=0), 1.0)
    assert np.max(np.abs(X1 - X0) / scale) < 1e-7


def test_faults_of_any_type_on_any_follower_are_one_structure(tmp_path):
    """With fault_slots, moving faults between followers and changing their types leaves
    the structure key (what the compiled library depends on) unchanged; without, it does not."""
    pytest.importorskip("generated.api")
    from generated import api
    from symbolic.parameters import layout_of, param_values, structure_key

    moved = {
        0: [ONE["intermittent"]],
        2: [dict(ONE["abrupt"], onset=0.1), dict(ONE["bias"], onset=0.2)],
        3: [],
    }
    variants = {}
    for slots in (None, 2):
        for name, faults in (("file", {}), ("moved", moved), ("none", dict.fromkeys(range(5), []))):
            data = tomllib.loads((SCENARIOS / "faults-example.toml").read_text())
            for i, fl in faults.items():
                data["followers"][i]["faults"] = fl
            if slots is not None:
                data["options"]["fault_slots"] = slots
            variants[slots, name] = scenario_from_dict(data, path=tmp_path / "x.toml", sha256=name)
    gains, _ = api.ensure_gains(variants[None, "file"], tmp_path)
    keys = {k: structure_key(sc, gains) for k, sc in variants.items()}
    assert keys[2, "file"] == keys[2, "moved"] == keys[2, "none"]
    assert keys[None, "file"] != keys[None, "moved"]
    sizes = {layout_of(variants[2, name]).size for name in ("file", "moved", "none")}
    assert len(sizes) == 1
    p_file, p_moved = (param_values(variants[2, name], gains) for name in ("file", "moved"))
    assert not np.array_equal(p_file, p_moved)  # the faults are in the numbers


def test_summary_names_the_slots_and_shows_g_and_f_as_written(tmp_path):
    from core.summary import summarize

    text = summarize(_example(tmp_path, slots=2))
    assert "fault slots = 2" in text
    assert "0.95 x the faults below (generic form, 2 fault slots)" in text
    assert "g(t) = 0.95 (generic form, 2 fault slots)" in text  # follower 5: no fault
    assert "mod(" not in text and "step(" not in text  # the slots' trees are not printed
    assert "fault slots" not in summarize(_example(tmp_path, slots=None))
