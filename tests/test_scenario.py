"""Scenario files: the paper's scenario loads with Table 2's values; every bad input is one line.

Each bad-input test checks the loader's error names the key, and that the CLI
``python -m symbolic summary BAD.toml`` exits 2 with one stderr line and no traceback.
"""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.errors import ExpressionError, ScenarioError, ToolkitError, run_cli
from core.scenario import load_scenario
from symbolic.__main__ import main

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "scenarios" / "paper.toml"
PAPER_CSV = ROOT / "scenarios" / "paper-csv.toml"


# --------------------------------------------------------------------------- helpers
def set_line(text: str, key: str, value: str, count: int = 1) -> str:
    """Replace the first ``count`` lines ``key = ...`` (a single-line value) by ``key = value``."""
    new, k = re.subn(rf"(?m)^{re.escape(key)}\s*=.*$", f"{key} = {value}", text, count=count)
    assert k == count, f"{key} not found in the paper scenario"
    return new


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def paper_text() -> str:
    return PAPER.read_text()


def check_bad(path: Path, key: str, capsys, *, words: tuple[str, ...] = ()) -> str:
    """The loader raises a one-line ToolkitError naming file and key; the CLI exits 2."""
    with pytest.raises(ToolkitError) as info:
        load_scenario(path)
    exc = info.value
    assert isinstance(exc, ScenarioError | ExpressionError)
    msg = str(exc)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: {key}"), msg
    for w in words:
        assert w in msg, msg
    rc = run_cli(main, ["summary", str(path)])
    out = capsys.readouterr()
    assert rc == 2
    assert out.out == ""
    lines = out.err.splitlines()
    assert len(lines) == 1 and lines[0] == f"error: {msg}"
    assert "Traceback" not in out.err
    return msg


# --------------------------------------------------------------------------- good files
def test_paper_scenario_has_table_2_values():
    s = load_scenario(PAPER)
    assert (s.N, s.n, s.m, s.p) == (5, 2, 2, 1)
    np.testing.assert_array_equal(s.leader.A0, [[0, 1], [0, 0]])
    np.testing.assert_array_equal(s.leader.B0, [[0], [1]])
    np.testing.assert_array_equal(s.leader.C0, [[1, 1], [2, 2]])
    np.testing.assert_array_equal(s.leader.eta0, [0, 0])
    assert [e.text for e in s.leader.u0] == ["2*cos(t)"] and s.leader.u0_trace is None
    assert s.leader.alpha == 2.0
    p0 = [[20, 15], [20, 20], [20, 15], [23, 14], [14, 21]]
    np.testing.assert_array_equal([f.p0 for f in s.followers], p0)
    # |b_i0| as printed (signs were lost in extraction, docs/reading.md, 'Table 2')
    np.testing.assert_array_equal(
        np.abs([f.b0 for f in s.followers]), [[4, 0], [1, 4], [3, 2], [2, 4], [3, 2]]
    )
    assert all(f.model == "two_link" and f.g.minimum == 0.95 for f in s.followers)
    assert s.followers[0].params == {
        "m1": 0.5,
        "m2": 1.5,
        "r1": 1.0,
        "r2": 0.8,
        "J1": 5.0,
        "J2": 5.0,
        "g0": 9.81,
    }
    f_text = [f.f[0].text for f in s.followers[:4]]
    assert f_text == ["4*sin(2*t) + 1", "3*cos(t) + exp(-2*t)", "2*sin(t)", "4*cos(t)"]
    # d_i = sup |f_i| over the horizon, from independent closed forms
    np.testing.assert_allclose([f.d[0] for f in s.followers[:4]], [5, 4, 2, 4], rtol=1e-9)
    assert s.observer.lambda1 == 1.9 and s.observer.lambda2 == 2.0
    np.testing.assert_array_equal(s.observer.Q, [[35.4, 14.9]])
    assert s.observer.Theta is None  # "synthesize"
    np.testing.assert_array_equal(s.controller.Lambda, np.full((5, 2), 40.0))
    np.testing.assert_array_equal(s.controller.k1, np.full((5, 2), 20.0))
    np.testing.assert_array_equal(s.controller.k2, np.ones(5))
    assert s.integration.horizon == 20.0
    # the graph reaches every follower (Assumption 1) and is cooperative
    assert s.graph.N == 5 and not s.graph.signed and s.graph.pinning.sum() > 0


def test_loaded_scenario_is_frozen():
    s = load_scenario(PAPER)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "x"  # type: ignore[misc]
    with pytest.raises(ValueError):
        s.leader.A0[0, 0] = 5.0
    with pytest.raises(ValueError):
        s.controller.Lambda[0, 0] = 5.0


def test_csv_scenario_matches_the_expression():
    s = load_scenario(PAPER_CSV)
    tr = s.leader.u0_trace
    assert s.leader.u0 is None and tr is not None and tr.shape[1] == 2
    assert tr[0, 0] == 0.0 and tr[-1, 0] >= s.integration.horizon
    np.testing.assert_allclose(tr[:, 1], 2 * np.cos(tr[:, 0]), atol=1e-8)
    assert s.N == 5 and s.name == "paper-csv"
    # between rows u0 is linear: within h²/8 · max|ü0| = 0.02²/8 · 2 of the expression
    ts = np.linspace(0, 20, 777)
    expr = load_scenario(PAPER).leader
    np.testing.assert_allclose(s.leader.u0_numpy(ts), expr.u0_numpy(ts), atol=1.0001e-4)
    assert s.leader.u0_numpy(0.01).shape == (1,)
    assert expr.u0_numpy(0.5) == pytest.approx([2 * np.cos(0.5)])


def test_sup_bounds_are_not_undersampled(tmp_path):
    # sin(7.3 t) peaks between grid points; d must still be sup |f| = 1 (Assumption 3)
    text = set_line(paper_text(), "f", '["sin(7.3*t)", "0.5*cos(3.1*t + 0.2)"]')
    s = load_scenario(write(tmp_path, text, "ok.toml"))
    np.testing.assert_allclose(s.followers[0].d, [1.0, 0.5], rtol=1e-10)


def test_remembered_supremum_is_the_refined_one(tmp_path, monkeypatch):
    # the loader remembers sup |f| per (expression, times); a second load must not refine
    # again and must give the number a fresh refinement gives, to the bit
    import core.suprema as S

    text = set_line(paper_text(), "f", '["sin(7.3*t)", "0.5*cos(3.1*t + 0.2)"]')
    path = write(tmp_path, text, "ok.toml")
    S._expr_sup_of.cache_clear()
    refined = S.signal_sup
    calls = []
    monkeypatch.setattr(S, "signal_sup", lambda *a: calls.append(1) or refined(*a))
    first = load_scenario(path)
    assert calls and len(S._expr_sup_of.namespace) > 0
    n_first = len(calls)
    again = load_scenario(path)
    assert len(calls) == n_first  # every supremum of the second load came from the memory
    monkeypatch.setattr(S, "signal_sup", refined)
    grid = np.linspace(0.0, first.integration.horizon, 4001)  # the loader's grid
    for r, e in enumerate(first.followers[0].f):
        fresh = S.signal_sup(lambda t, e=e: np.abs(e.numpy(t)), S.sample_times(e, grid))
        assert again.followers[0].d[r] == first.followers[0].d[r] == fresh


def test_health_table_and_expression(tmp_path):
    text = set_line(paper_text(), "g", '"1 - 0.5*step(t - 8)"', count=2)  # followers 1 and 2
    text = set_line(text, "g", "[[0.0, 1.0], [5.0, 0.6], [12.0, 0.8]]")  # then follower 1 again
    s = load_scenario(write(tmp_path, text, "ok.toml"))
    g1, g2 = s.followers[0].g, s.followers[1].g
    assert g1.breakpoints == (5.0, 12.0) and g1.minimum == 0.6
    ts = np.array([0.0, 4.99, 5.0, 11.0, 12.0, 19.0])
    np.testing.assert_allclose(g1.expr.numpy(ts), [1, 1, 0.6, 0.6, 0.8, 0.8])
    assert g2.breakpoints == (8.0,) and g2.minimum == pytest.approx(0.5)
    assert s.breakpoints() == (5.0, 8.0, 12.0)
    assert s.followers[2].g.minimum == 0.95


def test_scalar_f_applies_to_every_component(tmp_path):
    text = set_line(paper_text(), "f", '"4*cos(t)"')
    s = load_scenario(write(tmp_path, text, "ok.toml"))
    assert [e.text for e in s.followers[0].f] == ["4*cos(t)", "4*cos(t)"]


def test_signed_graph_is_accepted(tmp_path):
    text = re.sub(
        r"(?s)adjacency = \[.*?\n\]",
        "adjacency = [[0, 0, 0, 0, 0], [1, 0, 0, 0, 0], [-1, 0, 0, 0, 0], [0, 1, 0, 0, 0],"
        " [0, 0, 0, 1, 0]]",
        paper_text(),
    )
    s = load_scenario(write(tmp_path, text, "ok.toml"))
    assert s.graph.signed and s.graph.adjacency[2, 0] == -1


def test_three_dimensional_uav_scenario(tmp_path):
    text = """
[leader]
A0 = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]
B0 = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
C0 = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
u0 = ["cos(t)", "sin(t)", "0"]
alpha = 1.0
[graph]
adjacency = [[0, 0], [1, 0]]
pinning = [1, 0]
[[followers]]
model = "point_mass_3d"
params = {m = 2.0}
p0 = [0, 0, 10]
b0 = [1, 0, 0]
[[followers]]
model = "point_mass_3d"
p0 = [0, 1, 10]
b0 = [-1, 0, 0]
g = [[0.0, 1.0], [3.0, 0.7]]
f = ["0", "0", "0.5*sin(t)"]
"""
    s = load_scenario(write(tmp_path, text, "uav3d.toml"))
    assert (s.N, s.n, s.m, s.p) == (2, 3, 3, 3)
    assert s.followers[0].params == {"m": 2.0, "g0": 9.81}
    np.testing.assert_allclose(s.followers[1].d, [0, 0, 0.5])
    assert s.observer.lambda1 is None and s.observer.Q is None  # defaults: synthesize


# --------------------------------------------------------------------------- bad files
def test_malformed_toml(tmp_path, capsys):
    path = write(tmp_path, paper_text().replace("[observer]", "[observer", 1))
    check_bad(path, "(file)", capsys, words=("malformed TOML",))


def test_unknown_key(tmp_path, capsys):
    path = write(tmp_path, paper_text().replace("[leader]\n", '[leader]\ncolour = "red"\n', 1))
    check_bad(path, "leader.colour", capsys, words=("unknown key",))


def test_unknown_top_level_key(tmp_path, capsys):
    path = write(tmp_path, "extra = 1\n" + paper_text())
    check_bad(path, "extra", capsys, words=("unknown key",))


@pytest.mark.parametrize(
    ("key", "value", "where"),
    [
        ("B0", "[[0.0], [1.0], [2.0]]", "leader.B0"),
        ("C0", "[[1.0, 1.0, 0.0], [2.0, 2.0, 0.0]]", "leader.C0"),
        ("A0", "[[0.0, 1.0], [0.0]]", "leader.A0"),
        ("Q", "[[35.4, 14.9, 1.0]]", "observer.Q"),
        ("Theta", "[[1.0], [2.0]]", "observer.Theta"),
        ("p0", "[20.0, 15.0, 1.0]", "followers[1].p0"),
    ],
)
def test_wrong_matrix_dimensions(tmp_path, capsys, key, value, where):
    path = write(tmp_path, set_line(paper_text(), key, value))
    check_bad(path, where, capsys)


@pytest.mark.parametrize(
    ("key", "value", "where"),
    [
        ("pinning", "[1.0, 0.0, 0.0, 0.0]", "graph.pinning"),
        ("alpha1", "[1.0, 1.0, 1.0]", "observer.alpha1"),
        ("Lambda", "[40.0, 40.0]", "controller.Lambda"),
        ("ghat", "[1.0, 1.0, 1.0, 1.0, 1.0, 1.0]", "initial.ghat"),
    ],
)
def test_N_inconsistent_across_sections(tmp_path, capsys, key, value, where):
    path = write(tmp_path, set_line(paper_text(), key, value))
    check_bad(path, where, capsys, words=("entries",))


def test_N_inconsistent_follower_count(tmp_path, capsys):
    text = paper_text()
    cut = text.rindex("[[followers]]")
    rest = text[cut:]
    text = text[:cut] + rest[rest.index("[observer]") :]  # drop follower 5
    check_bad(write(tmp_path, text), "followers", capsys, words=("4 followers", "5x5"))


@pytest.mark.parametrize(
    ("value", "where", "word"),
    [
        ("1.2", "followers[1].g", "1.2"),
        ("0.0", "followers[1].g", "outside (0, 1]"),
        ("[[0.0, 1.0], [5.0, 1.5]]", "followers[1].g[1][1]", "1.5"),
        ("[[0.0, 1.0], [5.0, -0.2]]", "followers[1].g[1][1]", "outside (0, 1]"),
        ('"1 - 0.1*t"', "followers[1].g", "outside (0, 1]"),  # reaches -1 at t = 20
        ('"0.5 + 0.6*step(t - 3)"', "followers[1].g", "1.1"),
    ],
)
def test_health_outside_unit_interval(tmp_path, capsys, value, where, word):
    path = write(tmp_path, set_line(paper_text(), "g", value))
    check_bad(path, where, capsys, words=(word,))


@pytest.mark.parametrize(
    ("key", "value", "where", "word"),
    [
        ("lambda1", "-1.9", "observer.lambda1", "not positive"),
        ("lambda2", "nan", "observer.lambda2", "not finite"),
        ("k1", "nan", "controller.k1", "not finite"),
        ("k2", "-1.0", "controller.k2", "not positive"),
        ("Lambda", "[40.0, 40.0, -1.0, 40.0, 40.0]", "controller.Lambda[2]", "not positive"),
        ("k1", "[20.0, 20.0, 20.0, [20.0, nan], 20.0]", "controller.k1[3][1]", "not finite"),
        ("Q", "[[35.4, nan]]", "observer.Q[0][1]", "not finite"),
        ("lambda1", "inf", "observer.lambda1", "not finite"),
        ("phi0", "-1.0", "observer.phi0", "not positive"),
    ],
)
def test_negative_or_nan_gains(tmp_path, capsys, key, value, where, word):
    path = write(tmp_path, set_line(paper_text(), key, value))
    check_bad(path, where, capsys, words=(word,))


def test_unreachable_follower(tmp_path, capsys):
    # follower 5 hears nobody and is not pinned
    text = re.sub(
        r"(?s)adjacency = \[.*?\n\]",
        "adjacency = [[0, 0, 0, 0, 0], [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], [0, 1, 1, 0, 0],"
        " [0, 0, 0, 0, 0]]",
        paper_text(),
    )
    text = set_line(text, "pinning", "[1.0, 0.0, 0.0, 0.0, 0.0]")
    check_bad(write(tmp_path, text), "graph", capsys, words=("follower(s) 5", "Assumption 1"))


def test_unreachable_cycle(tmp_path, capsys):
    # followers 2 and 3 hear each other but nobody connects them to the leader
    text = re.sub(
        r"(?s)adjacency = \[.*?\n\]",
        "adjacency = [[0, 0, 0, 0, 0], [0, 0, 1, 0, 0], [0, 1, 0, 0, 0], [1, 0, 0, 0, 0],"
        " [1, 0, 0, 0, 0]]",
        paper_text(),
    )
    text = set_line(text, "pinning", "[1.0, 0.0, 0.0, 0.0, 0.0]")
    check_bad(write(tmp_path, text), "graph", capsys, words=("follower(s) 2, 3",))


def _csv_scenario(tmp_path: Path, csv_text: str) -> Path:
    (tmp_path / "trace.csv").write_text(csv_text)
    text = set_line(PAPER_CSV.read_text(), "u0_csv", '"trace.csv"')
    return write(tmp_path, text)


def test_non_monotone_csv_trace(tmp_path, capsys):
    path = _csv_scenario(tmp_path, "t,u0_1\n0.0,1.0\n5.0,1.5\n4.0,1.0\n20.0,0.0\n")
    check_bad(path, "leader.u0_csv", capsys, words=("trace.csv line 4", "does not increase"))


def test_repeated_time_in_csv_trace(tmp_path, capsys):
    path = _csv_scenario(tmp_path, "# comment\n0.0,1.0\n5.0,1.5\n5.0,1.0\n20.0,0.0\n")
    check_bad(path, "leader.u0_csv", capsys, words=("line 4",))


@pytest.mark.parametrize(
    ("csv_text", "word"),
    [
        ("t,u0_1\n0.0,1.0\n10.0,1.0\n", "covers [0, 10]"),
        ("t,u0_1\n0.0,1.0\n20.0,abc\n", "not numeric"),
        ("t,u0_1\n0.0,1.0\n20.0,nan\n", "not finite"),
        ("t,u0_1\n0.0,1.0,2.0\n20.0,1.0\n", "3 columns"),
        ("t,u0_1\n0.0,1.0\n20.0,2.5\n", "alpha"),
        ("t,u0_1\n0.0,1.0\n", "fewer than two"),
        ("\x00\x01\x02", "trace.csv"),
    ],
)
def test_other_bad_csv_traces(tmp_path, capsys, csv_text, word):
    path = _csv_scenario(tmp_path, csv_text)
    key = "leader.alpha" if word == "alpha" else "leader.u0_csv"
    check_bad(path, key, capsys, words=(word,))


def test_missing_csv_trace(tmp_path, capsys):
    text = set_line(PAPER_CSV.read_text(), "u0_csv", '"nope.csv"')
    check_bad(write(tmp_path, text), "leader.u0_csv", capsys, words=("cannot read nope.csv",))


@pytest.mark.parametrize(
    ("key", "value", "where", "token"),
    [
        ("f", '["__import__(\'os\')", "0"]', "followers[1].f[0]", "__import__"),
        ("f", '["0", "t.real"]', "followers[1].f[1]", ".real"),
        ("u0", '["(lambda x: x)(t)"]', "leader.u0[0]", "lambda"),
        ("g", '"0.9 + 0*foo(t)"', "followers[1].g", "foo"),
        ("f", '["[x for x in (t,)]", "0"]', "followers[1].f[0]", "comprehension"),
    ],
)
def test_rejected_expression(tmp_path, capsys, key, value, where, token):
    path = write(tmp_path, set_line(paper_text(), key, value))
    check_bad(path, where, capsys, words=(f"token {token!r}",))


def test_u0_beyond_alpha(tmp_path, capsys):
    path = write(tmp_path, set_line(paper_text(), "u0", '["2.5*cos(t)"]'))
    check_bad(path, "leader.alpha", capsys, words=("2.5",))


def test_unbounded_disturbance(tmp_path, capsys):
    path = write(tmp_path, set_line(paper_text(), "f", '["log(t - 1)", "0"]'))
    check_bad(path, "followers[1].f[0]", capsys, words=("not finite",))


def test_given_d_below_sup_f(tmp_path, capsys):
    text = paper_text().replace('f = ["4*sin(2*t) + 1"', 'd = [4.0, 5.0]\nf = ["4*sin(2*t) + 1"', 1)
    check_bad(write(tmp_path, text), "followers[1].d", capsys, words=("5 > d = 4",))


def test_projection_needs_g_min_below_health(tmp_path, capsys):
    text = set_line(paper_text(), "ghat_law", '"projection"')
    text = set_line(text, "g_min", "0.97")
    check_bad(write(tmp_path, text), "controller.g_min", capsys, words=("0.95",))


@pytest.mark.parametrize(
    ("key", "value", "where"),
    [
        ("model", '"quadcopter"', "followers[1].model"),
        ("model", '"point_mass_3d"', "followers[1].model"),  # n = 3 but C0 has 2 rows
        ("sign", '"fuzzy"', "options.sign"),
        ("feedforward", '"yes"', "options.feedforward"),
        ("name", '"../escape"', "name"),
        ("max_steps", "1.5", "integration.max_steps"),
        ("lambda1", '"synthesise"', "observer.lambda1"),
        ("k2", '"synthesize"', "controller.k2"),
    ],
)
def test_other_bad_values(tmp_path, capsys, key, value, where):
    path = write(tmp_path, set_line(paper_text(), key, value))
    check_bad(path, where, capsys)


def test_bad_model_parameter(tmp_path, capsys):
    text = paper_text().replace('model = "two_link"', 'model = "two_link"\nparams = {m1 = -0.5}', 1)
    check_bad(write(tmp_path, text), "followers[1].params.m1", capsys, words=("not positive",))
    text = paper_text().replace('model = "two_link"', 'model = "two_link"\nparams = {mass = 1}', 1)
    check_bad(write(tmp_path, text), "followers[1].params.mass", capsys, words=("unknown key",))


def test_missing_file_and_not_utf8(tmp_path, capsys):
    check_bad(tmp_path / "none.toml", "(file)", capsys, words=("cannot be read",))
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe\x00name")
    check_bad(bad, "(file)", capsys)


def test_cli_process_exit_status(tmp_path):
    """A real process (the good path runs in-process in the summary test below)."""
    bad = write(tmp_path, set_line(paper_text(), "lambda1", "nan"))
    res = subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(bad)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2
    assert res.stdout == "" and len(res.stderr.splitlines()) == 1
    assert "observer.lambda1" in res.stderr and "Traceback" not in res.stderr


def test_summary_lists_the_scenario_facts(capsys):
    assert run_cli(main, ["summary", str(PAPER)]) == 0
    out = capsys.readouterr().out
    for needle in (
        "N = 5",
        "n = 2",
        "m = 2",
        "p = 1",
        "1->2",  # an edge
        "pinned",
        "M bounds: lambda_min >= 5.0769, lambda_max <= 11.2431",
        "Property 2 exact",
        "g(t) = 0.95",
        "f(t) = [4*sin(2*t) + 1",
        "Theta = synthesize",
        "lambda1 = 1.9 (given)",
        "ghat law",
        "integration  native",
    ):
        assert needle in out, needle
    assert math.isfinite(float(re.search(r"horizon = ([0-9.]+) s", out).group(1)))


def test_summary_names_the_follower_whose_model_fails_property_1(tmp_path, capsys):
    import sympy as sp

    from core.models import REGISTRY, ModelSpec, register

    def lag(prm):  # M = k - 1: positive definite only for k > 1
        x, v = sp.symbols("x v", real=True)
        return sp.Rational(1, 2) * (sp.nsimplify(prm["k"]) - 1) * v**2, sp.Integer(0), [x], [v]

    register(ModelSpec(name="_test_spring", n=1, defaults={"k": 2.0}, lagrangian=lag))
    try:
        text = """
[leader]
A0 = [[0]]
B0 = [[1]]
C0 = [[1]]
u0 = ["0"]
alpha = 1
[graph]
adjacency = [[0, 0], [1, 0]]
pinning = [1, 0]
[[followers]]
model = "_test_spring"
p0 = [0]
b0 = [1]
[[followers]]
model = "_test_spring"
params = {k = 0.5}
p0 = [0]
b0 = [-1]
"""
        path = write(tmp_path, text)
        load_scenario(path)  # the file itself is well formed
        assert run_cli(main, ["summary", str(path)]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and f"{path}: followers[2].params: Property 1 fails" in err[0]
    finally:
        REGISTRY.pop("_test_spring", None)
