"""The fault library (``[[followers.faults]]``, docs/scenario-format.md 'Faults').

Independent truth: the closed forms of the documented faults, written here with
numpy (``g0 (1 - s [t >= t0])``, a clipped linear ramp, a pulse train) and the
documented composition rule (product of health factors, sum of biases); the
breakpoints are the documented switching times computed here; bad inputs are
refused by the command line with exit status 2 and one stderr line naming the key.
"""

from __future__ import annotations

import subprocess
import sys

import casadi as ca
import numpy as np
import pytest
from helpers import PAPER, ROOT

from core.expressions import parse_expression
from core.faults import FAULT
from core.scenario import load_scenario
from generated import api
from generated.values import CodegenSettings

HORIZON = 10.0
BASE = f"""
[leader]
A0 = [[0, 1], [0, 0]]
B0 = [[0], [1]]
C0 = [[1, 0], [0, 1]]
u0 = ["cos(t)"]
alpha = 1
[graph]
adjacency = [[0, 0], [1, 0]]
pinning = [1, 0]
[integration]
horizon = {HORIZON}
[[followers]]
model = "point_mass_2d"
p0 = [0, 0]
b0 = [1, 0]
g = 0.9
f = ["sin(t)", "2"]
"""
SECOND = """
[[followers]]
model = "point_mass_2d"
p0 = [1, 0]
b0 = [0, 1]
"""


def _fault(**keys) -> str:
    body = "".join(f"{k} = {_toml(v)}\n" for k, v in keys.items())
    return "[[followers.faults]]\n" + body


def _toml(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def _load(tmp_path, first: str = "", second: str = ""):
    path = tmp_path / "faults.toml"
    path.write_text(BASE + first + SECOND + second)
    return load_scenario(path)


def _casadi(expr, ts: np.ndarray) -> np.ndarray:
    t = ca.SX.sym("t")
    fun = ca.Function("e", [t], [ca.SX(expr.casadi(t))])
    return np.array([float(fun(x)) for x in ts])


def _both(expr, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The expression on ``ts`` through numpy and through CasADi."""
    return np.broadcast_to(expr.numpy(ts), ts.shape).astype(float), _casadi(expr, ts)


def _around(*times: float) -> np.ndarray:
    """A grid over the horizon plus each time, just before it and exactly at it."""
    extra = [x for b in times for x in (b, np.nextafter(b, -np.inf), b - 1e-6, b + 1e-6)]
    ts = np.concatenate([np.linspace(0.0, HORIZON, 401), extra])
    return np.unique(ts[(ts >= 0) & (ts <= HORIZON)])


def _assert_equal(expr, truth: np.ndarray, ts: np.ndarray) -> None:
    for got in _both(expr, ts):
        np.testing.assert_allclose(got, truth, rtol=1e-14, atol=1e-14)


# --------------------------------------------------------------------------- each type
def test_abrupt_drops_health_at_onset(tmp_path):
    sc = _load(tmp_path, _fault(type="abrupt", onset=3.5, severity=0.4))
    ts = _around(3.5)
    truth = np.where(ts >= 3.5, 0.9 * 0.6, 0.9)
    _assert_equal(sc.followers[0].g.expr, truth, ts)
    assert sc.followers[0].g.minimum == pytest.approx(0.54, rel=1e-14)
    assert sc.breakpoints() == (3.5,)
    assert np.all(sc.followers[1].g.expr.numpy(ts) == 1.0)  # the other follower is healthy


def test_ramp_falls_linearly_to_the_final_health(tmp_path):
    sc = _load(tmp_path, _fault(type="ramp", onset=2.0, duration=4.0, severity=0.5))
    ts = _around(2.0, 6.0)
    truth = 0.9 * (1 - 0.5 * np.clip((ts - 2.0) / 4.0, 0.0, 1.0))
    _assert_equal(sc.followers[0].g.expr, truth, ts)
    assert sc.followers[0].g.expr.numpy(4.0) == pytest.approx(0.9 * 0.75, rel=1e-14)  # midway
    assert sc.followers[0].g.minimum == pytest.approx(0.45, rel=1e-12)
    assert sc.breakpoints() == (2.0, 6.0)


def test_ramp_ending_after_the_horizon_has_only_its_start_as_breakpoint(tmp_path):
    sc = _load(tmp_path, _fault(type="ramp", onset=8.0, duration=4.0, severity=0.5))
    assert sc.breakpoints() == (8.0,)
    end = 0.9 * (1 - 0.5 * 0.5)  # half-way down at the horizon
    assert sc.followers[0].g.minimum == pytest.approx(end, rel=1e-9)


def _pulse_truth(ts: np.ndarray, onset: float, period: float, duty: float) -> np.ndarray:
    """1 while the fault is on: the pulses [onset + k P, onset + k P + duty P)."""
    on = np.zeros(ts.shape, dtype=bool)
    k = 0
    while onset + k * period < HORIZON:
        start = onset + k * period
        on |= (ts >= start) & (ts < start + duty * period)
        k += 1
    return on


def test_intermittent_switches_on_and_off_with_period_and_duty(tmp_path):
    onset, period, duty, s = 1.5, 2.0, 0.25, 0.3
    sc = _load(
        tmp_path, _fault(type="intermittent", onset=onset, period=period, duty=duty, severity=s)
    )
    switches = []
    for k in range(5):  # pulses start at 1.5, 3.5, 5.5, 7.5, 9.5 < 10
        start = onset + k * period
        switches += [start, start + duty * period]
    ts = _around(*switches)
    truth = np.where(_pulse_truth(ts, onset, period, duty), 0.9 * (1 - s), 0.9)
    _assert_equal(sc.followers[0].g.expr, truth, ts)
    # off time of the last pulse (10.0) is the horizon itself: not a breakpoint
    assert sc.breakpoints() == tuple(sorted(b for b in switches if b < HORIZON))
    # a reading independent of the pulse list: on iff (t - onset) mod P < duty P
    mid = np.array([1.6, 2.4, 3.9, 4.2, 6.0, 9.9])
    by_mod = (mid >= onset) & (np.mod(mid - onset, period) < duty * period)
    assert np.array_equal(sc.followers[0].g.expr.numpy(mid) < 0.9, by_mod)


def test_bias_adds_its_amplitude_per_component_from_onset(tmp_path):
    sc = _load(tmp_path, _fault(type="bias", onset=4.25, amplitude=[0.5, -2.0]))
    ts = _around(4.25)
    f = sc.followers[0].f
    _assert_equal(f[0], np.sin(ts) + np.where(ts >= 4.25, 0.5, 0.0), ts)
    _assert_equal(f[1], 2.0 + np.where(ts >= 4.25, -2.0, 0.0), ts)
    assert sc.breakpoints() == (4.25,)
    assert np.all(sc.followers[0].g.expr.numpy(ts) == 0.9)  # a bias leaves g alone
    # the bound d of Assumption 3 includes the bias: sup |2 - 2 step| = 2, sup |sin + 0.5| = 1.5
    np.testing.assert_allclose(sc.followers[0].d, [1.5, 2.0], rtol=1e-9)


@pytest.mark.parametrize("onset", [0.1, 0.3, 0.7, 1.1, 2.9, 5.1, 7.3, 9.7])
def test_bias_breakpoint_is_the_onset_exactly(tmp_path, onset):
    """The numerically found root of step(t - onset) in f is replaced by the onset itself."""
    sc = _load(tmp_path, _fault(type="bias", onset=onset, amplitude=[1.0, 1.0]))
    assert sc.breakpoints() == (onset,)


# --------------------------------------------------------------------------- composition
def test_several_faults_compose_on_one_and_on_several_followers(tmp_path):
    first = (
        _fault(type="abrupt", onset=2.0, severity=0.3)
        + _fault(type="ramp", onset=4.0, duration=2.0, severity=0.2)
        + _fault(type="intermittent", onset=5.0, period=3.0, duty=0.5, severity=0.1)
        + _fault(type="bias", onset=1.0, amplitude=[1.0, 2.0])
        + _fault(type="bias", onset=3.0, amplitude=[-0.25, 0.5])
    )
    second = _fault(type="abrupt", onset=6.5, severity=0.5)
    sc = _load(tmp_path, first, second)
    switches = [2.0, 4.0, 6.0, 5.0, 6.5, 8.0, 9.5, 1.0, 3.0]
    ts = _around(*switches)
    abrupt = np.where(ts >= 2.0, 0.7, 1.0)
    ramp = 1 - 0.2 * np.clip((ts - 4.0) / 2.0, 0, 1)
    pulses = np.where(_pulse_truth(ts, 5.0, 3.0, 0.5), 0.9, 1.0)
    _assert_equal(sc.followers[0].g.expr, 0.9 * abrupt * ramp * pulses, ts)
    bias = np.where(ts >= 1.0, 1.0, 0.0)[:, None] * [1.0, 2.0]
    bias += np.where(ts >= 3.0, 1.0, 0.0)[:, None] * [-0.25, 0.5]
    _assert_equal(sc.followers[0].f[0], np.sin(ts) + bias[:, 0], ts)
    _assert_equal(sc.followers[0].f[1], 2.0 + bias[:, 1], ts)
    _assert_equal(sc.followers[1].g.expr, np.where(ts >= 6.5, 0.5, 1.0), ts)
    assert sc.breakpoints() == tuple(sorted(set(switches)))
    assert sc.followers[0].g.minimum == pytest.approx(0.9 * 0.7 * 0.8 * 0.9, rel=1e-12)


def test_faults_multiply_a_health_table(tmp_path):
    text = BASE.replace("g = 0.9", "g = [[0.0, 1.0], [5.0, 0.8]]")
    path = tmp_path / "table.toml"
    path.write_text(text + _fault(type="abrupt", onset=2.0, severity=0.5) + SECOND)
    sc = load_scenario(path)
    ts = _around(2.0, 5.0)
    table = np.where(ts >= 5.0, 0.8, 1.0)
    _assert_equal(sc.followers[0].g.expr, table * np.where(ts >= 2.0, 0.5, 1.0), ts)
    assert sc.breakpoints() == (2.0, 5.0)


def test_composed_text_names_the_same_function(tmp_path):
    """Consistency check: the text (the closed loop shares evaluations by text) parses
    back to the function it names."""
    sc = _load(
        tmp_path,
        _fault(type="intermittent", onset=0.5, period=1.5, duty=0.4, severity=0.2)
        + _fault(type="bias", onset=1.0, amplitude=[-1.0, 3.0]),
    )
    ts = _around(0.5, 1.1, 2.0)
    for e in (sc.followers[0].g.expr, *sc.followers[0].f):
        again = parse_expression(e.text)
        np.testing.assert_array_equal(again.numpy(ts), e.numpy(ts))


def test_no_faults_leave_g_and_f_unchanged(tmp_path):
    sc = _load(tmp_path)
    assert sc.followers[0].g.expr.text == "0.9" and sc.followers[0].faults == ()
    assert [e.text for e in sc.followers[0].f] == ["sin(t)", "2"]
    assert sc.breakpoints() == ()


# --------------------------------------------------------------------------- bad inputs
BAD = [
    (_fault(type="drop", onset=1.0, severity=0.5), "faults[1].type", "not a fault type"),
    (_fault(onset=1.0, severity=0.5), "faults[1].type", "missing"),
    (_fault(type="abrupt", onset=1.0, severity=0.5, period=2.0), "faults[1].period", "unknown"),
    (_fault(type="abrupt", onset=1.0), "faults[1].severity", "missing"),
    (_fault(type="abrupt", onset=12.0, severity=0.5), "faults[1].onset", "beyond the horizon"),
    (_fault(type="abrupt", onset=-1.0, severity=0.5), "faults[1].onset", "negative"),
    (_fault(type="abrupt", onset=1.0, severity=1.0), "faults[1].severity", "outside [0, 1)"),
    (_fault(type="ramp", onset=1.0, severity=-0.1, duration=1.0), "severity", "outside [0, 1)"),
    (_fault(type="ramp", onset=1.0, severity=0.1, duration=0.0), "duration", "not positive"),
    (
        _fault(type="intermittent", onset=1.0, severity=0.1, period=0.0, duty=0.5),
        "faults[1].period",
        "not positive",
    ),
    (
        _fault(type="intermittent", onset=1.0, severity=0.1, period=1.0, duty=1.0),
        "faults[1].duty",
        "outside (0, 1)",
    ),
    (
        _fault(type="intermittent", onset=0.0, severity=0.1, period=0.001, duty=0.5),
        "faults[1].period",
        "switches",
    ),
    (_fault(type="bias", onset=1.0, amplitude=[1.0]), "faults[1].amplitude", "1 entries"),
    (_fault(type="bias", onset=1.0, amplitude=1.0), "faults[1].amplitude", "not a list"),
    (
        _fault(type="abrupt", onset=1.0, severity=0.5)
        + _fault(type="bias", onset="soon", amplitude=[0, 0]),
        "faults[2].onset",
        "not a number",
    ),
    ("faults = 3\n", "followers[1].faults", "not an array of tables"),
]


@pytest.mark.parametrize(("fault", "key", "words"), BAD, ids=lambda v: str(v)[:40])
def test_bad_fault_is_one_line_from_the_command_line(tmp_path, fault, key, words):
    path = tmp_path / "bad.toml"
    path.write_text(BASE + fault + SECOND)
    res = subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert f"{key}:" in lines[0] and words in lines[0] and "(expected " in lines[0], lines[0]
    assert res.stdout == ""


def test_g_min_above_a_faulted_health_is_refused(tmp_path):
    """controller.g_min must not exceed the smallest health, faults included."""
    path = tmp_path / "gmin.toml"
    path.write_text(
        BASE
        + _fault(type="abrupt", onset=1.0, severity=0.6)  # 0.9 * 0.4 = 0.36 < g_min 0.5
        + SECOND
        + '[options]\nghat_law = "projection"\n[controller]\ng_min = 0.5\n'
    )
    res = subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2 and "controller.g_min" in res.stderr and "0.36" in res.stderr


# --------------------------------------------------------------------------- summary, docs
def test_summary_lists_the_faults():
    res = subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(ROOT / "scenarios/faults-example.toml")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert "fault 1: abrupt loss 0.3 from t = 0.4" in out
    assert "fault 1: ramp loss 0.25 from t = 0.2 over 3 s" in out
    assert "fault 1: intermittent loss 0.3 from t = 0.3, period 1 s, duty 0.3" in out
    assert "fault 2: bias [1, -0.5] from t = 0.45" in out


def test_documented_fault_keys_are_the_declared_ones():
    text = (ROOT / "docs" / "scenario-format.md").read_text()
    section = text[text.index("## Faults") :]
    section = section[: section.index("\n## ")]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        if len(cells) == 4 and cells[0].startswith("`"):
            rows.append((cells[0].strip("`"), cells[1], cells[2]))
    assert [r[0] for r in rows] == list(FAULT)
    for key, typ, default in rows:
        assert typ == FAULT[key].type_text(), key
        assert default == FAULT[key].default.text, key


# --------------------------------------------------------------------------- a run
def test_short_run_with_an_intermittent_fault_reaches_the_horizon(tmp_path):
    text = PAPER.read_text()
    anchor = 'f = ["2*sin(t)", "2*sin(t)"]\n'
    fault = _fault(type="intermittent", onset=0.1, period=0.4, duty=0.5, severity=0.3)
    path = tmp_path / "intermittent.toml"
    path.write_text(text.replace(anchor, anchor + fault))
    starts = [0.1 + k * 0.4 for k in range(50)]  # horizon 20 s: pulses start up to 19.7
    switches = sorted(x for on in starts for x in (on, on + 0.5 * 0.4) if x < 20.0)
    assert load_scenario(path).breakpoints() == tuple(switches)
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path / "build"))
    res = api.run(
        path,
        overrides={"integration.horizon": 1.5},
        codegen=cg,
        out_root=tmp_path / "out",
        progress=False,
    )
    assert res.trajectory.complete, res.trajectory.message
    assert res.trajectory.t[-1] == 1.5 and res.meta["complete"]
    assert np.all(np.isfinite(res.trajectory.x))
