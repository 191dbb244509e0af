"""Study files and the sampler (sweep/): distributions, reproducibility, random graphs,
one-line errors and written scenario files.

Independent truths: the distributions' analytic moments and supports, a reachability
test written here (not core.graph's), tomllib reading the written files, and the normal
scenario loader reading them back.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from helpers import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import run_cli
from core.scenario import load_scenario
from sweep.__main__ import main
from sweep.distributions import Distribution
from sweep.graphs import random_graph
from sweep.sampler import draw, samples, write_scenario
from sweep.study import load_study

EXAMPLE = ROOT / "studies" / "example.toml"
PAPER = (ROOT / "scenarios" / "paper.toml").as_posix()
TRACE = (ROOT / "scenarios" / "traces" / "operator.csv").as_posix()
DRAWS = 40_000


def _study(tmp_path: Path, body: str, head: str | None = None) -> Path:
    """A study file on the paper scenario: ``head`` (default base/count/seed) + ``body``."""
    if head is None:
        head = f'base = "{PAPER}"\ncount = 4\nseed = 7\n'
    p = tmp_path / "s.toml"
    p.write_text(head + body)
    return p


# --------------------------------------------------------------------------- distributions
def _draws(d: Distribution, n: int = DRAWS) -> np.ndarray:
    rng = np.random.default_rng(123)
    return np.array([draw(d, rng) for _ in range(n)])


def test_uniform_bounds_and_moments():
    x = _draws(Distribution("uniform", (2.0, 5.0)))
    assert x.min() >= 2.0 and x.max() <= 5.0
    sd_mean = 3 / math.sqrt(12) / math.sqrt(DRAWS)
    assert abs(x.mean() - 3.5) < 5 * sd_mean
    assert abs(x.var() - 9 / 12) < 0.02  # var of U(2, 5) = 3^2 / 12


def test_normal_moments():
    x = _draws(Distribution("normal", (-1.0, 2.0)))
    assert abs(x.mean() + 1.0) < 5 * 2.0 / math.sqrt(DRAWS)
    assert abs(x.std() - 2.0) < 0.05


def test_truncated_normal_bounds_and_analytic_mean():
    """DRAWS truncated-normal values lie in [lo, hi] with the analytic mean. They come from
    one sized draw (one scipy call: DRAWS calls of ~0.25 ms each took 10 s); a few hundred
    single draws go through the unsized path and must lie in [lo, hi] too."""
    mu, s, lo, hi = 0.0, 1.0, -0.5, 2.0
    x = np.array(
        draw(
            Distribution("normal", (mu, s), size=DRAWS, truncate=(lo, hi)),
            np.random.default_rng(123),
        )
    )
    assert x.shape == (DRAWS,) and x.min() >= lo and x.max() <= hi
    one = _draws(Distribution("normal", (mu, s), truncate=(lo, hi)), 300)
    assert one.shape == (300,) and one.min() >= lo and one.max() <= hi

    def pdf(z):
        return math.exp(-z * z / 2) / math.sqrt(2 * math.pi)

    def cdf(z):
        return 0.5 * (1 + math.erf(z / math.sqrt(2)))

    a, b = (lo - mu) / s, (hi - mu) / s
    mean = mu + s * (pdf(a) - pdf(b)) / (cdf(b) - cdf(a))  # truncated-normal mean
    assert abs(x.mean() - mean) < 5 * s / math.sqrt(DRAWS)


def test_integers_are_inclusive_and_uniform():
    x = _draws(Distribution("integers", (3, 6)))
    assert set(x.tolist()) == {3, 4, 5, 6}
    for k in range(3, 7):
        assert abs((x == k).mean() - 0.25) < 5 * math.sqrt(0.25 * 0.75 / DRAWS)


def test_choice_frequencies():
    x = [
        draw(Distribution("choice", ("a", "b", "c")), np.random.default_rng(k)) for k in range(6000)
    ]
    for v in "abc":
        assert abs(x.count(v) / 6000 - 1 / 3) < 5 * math.sqrt(2 / 9 / 6000)


def test_sized_draw_is_a_list_of_that_length():
    v = draw(Distribution("uniform", (0.0, 1.0), size=3), np.random.default_rng(0))
    assert isinstance(v, list) and len(v) == 3 and len(set(v)) == 3


# --------------------------------------------------------------------------- reproducibility
def test_same_seed_same_samples_and_subset_independent():
    study = load_study(EXAMPLE)
    full = [(s.id, s.seed, s.params) for s in samples(study)]
    again = [(s.id, s.seed, s.params) for s in samples(load_study(EXAMPLE))]
    assert full == again
    subset = [(s.id, s.seed, s.params) for s in samples(study, ids=[3, 1])]
    assert subset == [full[3], full[1]]
    assert len({json.dumps(p) for _, _, p in full}) == len(full)  # samples differ


def test_another_seed_gives_other_samples(tmp_path):
    text = EXAMPLE.read_text().replace("seed = 2026", "seed = 2027")
    text = text.replace("../scenarios/paper.toml", PAPER)
    other = tmp_path / "other.toml"
    other.write_text(text)
    a = next(samples(load_study(EXAMPLE))).params
    b = next(samples(load_study(other))).params
    assert a != b


def test_example_samples_respect_their_distributions():
    for s in samples(load_study(EXAMPLE)):
        assert s.reason is None and s.scenario is not None
        assert 1.0 <= s.params["operator.A"] <= 2.0
        assert np.all(s.scenario.controller.k1 == s.params["controller.k1"])
        assert 15.0 <= s.params["controller.k1"] <= 25.0
        for i, f in enumerate(s.scenario.followers):
            assert np.array_equal(f.p0, s.params[f"followers[{i + 1}].p0"])
            assert np.all((f.p0 >= 10.0) & (f.p0 <= 30.0))


# --------------------------------------------------------------------------- random graphs
def _reachable(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Followers reached from the leader: fixed point of reach |= (A @ reach > 0)."""
    reach = b > 0
    for _ in range(len(b)):
        reach = reach | (A @ reach.astype(float) > 0)
    return reach


@settings(max_examples=200, deadline=None)
@given(
    N=st.integers(1, 25),
    p=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_graph_has_a_spanning_tree_from_the_leader(N, p, seed):
    A, b = random_graph(N, p, 1.0, np.random.default_rng(seed))
    assert A.shape == (N, N) and b.shape == (N,)
    assert np.all(np.diag(A) == 0) and np.all(A >= 0) and np.all(b >= 0)
    assert _reachable(A, b).all()


def test_study_graphs_have_the_requested_sizes(tmp_path):
    path = _study(
        tmp_path,
        "[graph]\nN = [2, 7]\nedge_probability = 0.3\n",
        head=f'base = "{PAPER}"\ncount = 30\nseed = 1\n',
    )
    sizes = set()
    for s in samples(load_study(path)):
        assert s.reason is None, s.reason
        N = s.params["graph.N"]
        sizes.add(N)
        assert 2 <= N <= 7 and s.scenario.graph.N == N and len(s.scenario.followers) == N
        assert _reachable(s.scenario.graph.adjacency, s.scenario.graph.pinning).all()
    assert len(sizes) >= 4  # the range is explored


# --------------------------------------------------------------------------- operator input
def test_operator_traces_are_chosen_files(tmp_path):
    path = _study(tmp_path, f'[operator]\ntraces = ["{TRACE}"]\n')
    for s in samples(load_study(path)):
        assert s.reason is None, s.reason
        assert (
            s.scenario_data["leader"]["u0_csv"] == TRACE and "u0" not in s.scenario_data["leader"]
        )
        assert s.scenario.leader.u0_trace is not None


def test_operator_family_evaluates_to_the_drawn_parameters(tmp_path):
    body = (
        '[operator]\nu0 = ["A*cos(w*t + phi)"]\n'
        "params = { A = { uniform = [-2, 2] }, w = { uniform = [0.5, 1.5] },"
        " phi = { uniform = [0, 6.3] } }\n"
    )
    t = np.linspace(0.0, 20.0, 101)
    for s in samples(load_study(_study(tmp_path, body))):
        assert s.reason is None, s.reason
        A, w, phi = (s.params[f"operator.{k}"] for k in ("A", "w", "phi"))
        u0 = s.scenario.leader.u0[0].numpy(t)
        np.testing.assert_allclose(u0, A * np.cos(w * t + phi), rtol=0, atol=1e-12)


def test_sample_the_loader_refuses_carries_its_reason(tmp_path, capsys):
    # amplitudes above leader.alpha = 2: every sample breaks ||u0|| <= alpha
    path = _study(
        tmp_path, '[operator]\nu0 = ["A*cos(t)"]\nparams = { A = { uniform = [3, 4] } }\n'
    )
    got = list(samples(load_study(path)))
    assert all(s.scenario is None and "leader.alpha" in s.reason for s in got)
    assert run_cli(main, ["samples", str(path)]) == 0
    assert capsys.readouterr().out.count("refused") == 4


# --------------------------------------------------------------------------- bad input
BAD = [
    ("colour = 1\n", "colour"),
    ('[params]\n"controller.k1" = { uniform = [5, 1] }\n', "controller.k1"),
    ('[params]\n"controller.k1" = { normal = [5, -1] }\n', "controller.k1"),
    ('[params]\n"options.sign" = { choice = [] }\n', "options.sign"),
    ('[params]\n"controller.k1" = { gamma = [1, 2] }\n', "gamma"),
    ('[params]\n"controller.k1" = { normal = [1, 1], truncate = [2, 1] }\n', "truncate"),
    ('[params]\n"controller.kk1" = { uniform = [1, 2] }\n', "controller.kk1"),
    ('[params]\n"followers[9].p0" = { uniform = [1, 2], size = 2 }\n', "followers[9].p0"),
    ("[graph]\nN = 0\nedge_probability = 0.1\n", "graph.N"),
    ("[graph]\nN = [5, 3]\nedge_probability = 0.1\n", "graph.N"),
    ("[graph]\nN = 4\nedge_probability = 1.5\n", "graph.edge_probability"),
    ('[operator]\nu0 = ["A*cos(t)"]\nparams = { B = { uniform = [1, 2] } }\n', "operator.params.B"),
    ('[operator]\nu0 = ["A*evil(t)"]\nparams = { A = { uniform = [1, 2] } }\n', "operator.u0[0]"),
    ('[operator]\ntraces = ["missing.csv"]\n', "operator.traces[0]"),
    (
        '[operator]\nu0 = ["cos*t"]\nparams = { cos = { uniform = [1, 2] } }\n',
        "operator.params.cos",
    ),
]
BAD_HEAD = [
    (f'base = "{PAPER}"\ncount = 0\nseed = 1\n', "count"),
    (f'base = "{PAPER}"\ncount = -3\nseed = 1\n', "count"),
    ("count = 3\nseed = 1\n", "base"),
    ('base = "nowhere.toml"\ncount = 3\nseed = 1\n', "base"),
    (f'base = "{PAPER}"\ncount = 3\n', "seed"),
]


def _one_line_error(path: Path, capsys) -> str:
    assert run_cli(main, ["samples", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


@pytest.mark.parametrize(("body", "key"), BAD, ids=[k for _, k in BAD])
def test_bad_study_body_is_one_line_naming_the_key(tmp_path, capsys, body, key):
    assert key in _one_line_error(_study(tmp_path, body), capsys)


@pytest.mark.parametrize(
    ("head", "key"), BAD_HEAD, ids=[f"{k}-{i}" for i, (_, k) in enumerate(BAD_HEAD)]
)
def test_bad_study_head_is_one_line_naming_the_key(tmp_path, capsys, head, key):
    assert f": {key}: " in _one_line_error(_study(tmp_path, "", head=head), capsys)


def test_command_line_exit_status_two_and_one_stderr_line(tmp_path):
    path = _study(tmp_path, '[params]\n"controller.k1" = { uniform = [5, 1] }\n')
    proc = subprocess.run(
        [sys.executable, "-m", "sweep", "samples", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "controller.k1" in proc.stderr


# --------------------------------------------------------------------------- written files
def _same(a, b, path: str = "") -> None:
    """Recursive equality of scenario values (dataclasses, arrays, tuples, scalars)."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b), path
    elif isinstance(a, tuple | list):
        assert len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{k}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    else:
        assert a == b, path


def test_written_scenarios_load_and_equal_the_sample(tmp_path, capsys):
    study = load_study(EXAMPLE)
    assert run_cli(main, ["samples", str(EXAMPLE), "--write-scenarios", str(tmp_path)]) == 0
    capsys.readouterr()
    for s in samples(study):
        file = tmp_path / f"{s.scenario_data['name']}.toml"
        assert tomllib.loads(file.read_text()) == s.scenario_data
        loaded = load_scenario(file)
        assert loaded.path == str(file)
        _same(dataclasses.replace(loaded, path=s.scenario.path), s.scenario)
    assert not list(tmp_path.glob("*.tmp"))


def test_written_graph_study_round_trips(tmp_path):
    path = _study(tmp_path, "[graph]\nN = [1, 6]\nedge_probability = 0.5\n")
    for s in samples(load_study(path)):
        file = write_scenario(s, tmp_path / "out")
        _same(dataclasses.replace(load_scenario(file), path=s.scenario.path), s.scenario)


# --------------------------------------------------------------------------- [set], [faults]
#: severities up to 0.2: two faults on one follower keep 0.95 * 0.8^2 >= controller.g_min
FAULTS = """
[faults]
count = [1, 2]
types = ["abrupt", "ramp", "intermittent", "bias"]
followers = [2, 4]
onset = { uniform = [1.0, 15.0] }
severity = { uniform = [0.05, 0.2] }
duration = { uniform = [0.5, 4.0] }
period = { uniform = [0.5, 3.0] }
duty = { uniform = [0.2, 0.8] }
amplitude = { uniform = [-1.0, 1.0], size = 2 }
"""
#: each type's own keys and the closed interval its drawn values must lie in
RANGES = {
    "onset": (1.0, 15.0),
    "severity": (0.05, 0.2),
    "duration": (0.5, 4.0),
    "period": (0.5, 3.0),
    "duty": (0.2, 0.8),
}
OWN_KEYS = {
    "abrupt": {"onset", "severity"},
    "ramp": {"onset", "severity", "duration"},
    "intermittent": {"onset", "severity", "period", "duty"},
    "bias": {"onset", "amplitude"},
}


def test_fault_family_draws_faults_of_the_listed_types_on_the_listed_followers(tmp_path):
    head = f'base = "{PAPER}"\ncount = 120\nseed = 3\n'
    types, counts = [], set()
    for s in samples(load_study(_study(tmp_path, FAULTS, head=head))):
        assert s.reason is None, s.reason
        n = s.params["faults.count"]
        counts.add(n)
        loaded = [f.faults for f in s.scenario.followers]  # what the scenario loader read
        assert sum(len(x) for x in loaded) == n and not loaded[0] and not loaded[2]
        seen = {1: 0, 3: 0}
        for k in range(1, n + 1):
            who, kind = s.params[f"faults[{k}].follower"], s.params[f"faults[{k}].type"]
            assert who in (2, 4)
            fault = loaded[who - 1][seen[who - 1]]
            seen[who - 1] += 1
            drawn = {
                key[len(f"faults[{k}].") :] for key in s.params if key.startswith(f"faults[{k}].")
            }
            assert drawn - {"follower", "type"} == OWN_KEYS[kind] and fault.type == kind
            for key in OWN_KEYS[kind] - {"amplitude"}:
                lo, hi = RANGES[key]
                assert lo <= s.params[f"faults[{k}].{key}"] <= hi
                assert getattr(fault, key) == s.params[f"faults[{k}].{key}"]
            if kind == "bias":
                amp = s.params[f"faults[{k}].amplitude"]
                assert len(amp) == 2 and all(-1 <= a <= 1 for a in amp)
                assert tuple(fault.amplitude) == tuple(amp)
            types.append(kind)
    assert counts == {1, 2}
    for kind in OWN_KEYS:  # four equally likely types: binomial frequencies
        p, n = 0.25, len(types)
        assert abs(types.count(kind) / n - p) < 5 * math.sqrt(p * (1 - p) / n)


def test_drawn_abrupt_fault_sets_the_health_closed_form(tmp_path):
    body = FAULTS.replace('["abrupt", "ramp", "intermittent", "bias"]', '["abrupt"]')
    body = body.replace("count = [1, 2]", "count = 1")
    body = "\n".join(
        line
        for line in body.splitlines()
        if not line.startswith(("duration", "period", "duty", "amplitude"))
    )
    for s in samples(load_study(_study(tmp_path, body))):
        who, t0 = s.params["faults[1].follower"], s.params["faults[1].onset"]
        sev = s.params["faults[1].severity"]
        g = s.scenario.followers[who - 1].g.expr.numpy(np.array([t0 - 1e-9, t0, 19.0]))
        # h(t) = 1 before the onset, 1 - s from it on, times the base health 0.95
        np.testing.assert_allclose(g, [0.95, 0.95 * (1 - sev), 0.95 * (1 - sev)], rtol=1e-14)


def test_set_values_reach_every_sample(tmp_path):
    body = '[set]\n"controller.k2" = 2.5\n"followers[3].g" = 0.9\n'
    for s in samples(load_study(_study(tmp_path, body))):
        assert s.reason is None
        assert np.all(s.scenario.controller.k2 == 2.5)
        assert s.scenario_data["followers"][2]["g"] == 0.9
        assert "controller.k2" not in s.params  # fixed, not drawn


BAD_FAULTS = [
    (FAULTS.replace('"bias"]', '"stuck"]'), "faults.types"),
    (FAULTS.replace("severity = { uniform = [0.05, 0.2] }\n", ""), "faults.severity"),
    (FAULTS.replace("size = 2", "size = 3"), "faults.amplitude"),
    (FAULTS.replace("followers = [2, 4]", "followers = [2, 9]"), "faults.followers"),
    (FAULTS.replace('"intermittent", ', ""), "faults.duty"),  # no listed type takes duty
    (
        FAULTS.replace(
            "onset = { uniform = [1.0, 15.0] }", "onset = { uniform = [1.0, 15.0], size = 2 }"
        ),
        "faults.onset.size",
    ),
    (FAULTS.replace("count = [1, 2]", "count = -1"), "faults.count"),
    (
        FAULTS.replace("onset = { uniform = [1.0, 15.0] }", "onset = { uniform = [25.0, 30.0] }"),
        "faults.onset",
    ),
    ('[set]\n"controller.kk2" = 1.0\n', 'set."controller.kk2"'),
    ('[set]\n"followers[9].g" = 0.9\n', 'set."followers[9].g"'),
]


@pytest.mark.parametrize(
    ("body", "key"), BAD_FAULTS, ids=[f"{k}-{i}" for i, (_, k) in enumerate(BAD_FAULTS)]
)
def test_bad_faults_or_set_is_one_line_naming_the_key(tmp_path, capsys, body, key):
    assert f": {key}" in _one_line_error(_study(tmp_path, body), capsys)


# --------------------------------------------------------------------------- link losses
LOSSES = """
[graph]
N = [4, 8]
edge_probability = 0.3

[graph.losses]
count = [1, 3]
time = { uniform = [2.0, 12.0] }
recovery = { uniform = [1.0, 10.0] }
"""


def _topologies(A: np.ndarray, b: np.ndarray, switches: list[dict]):
    """Each graph in force, from the written switches (applied together at equal times)."""
    A, b = A.copy(), b.copy()
    yield A.copy(), b.copy()
    for t in sorted({s["time"] for s in switches}):
        for s in (s for s in switches if s["time"] == t):
            if s["neighbour"] == 0:
                b[s["follower"] - 1] = s["weight"]
            else:
                A[s["follower"] - 1, s["neighbour"] - 1] = s["weight"]
        yield A.copy(), b.copy()


def test_link_losses_are_links_of_the_graph_restored_with_their_weight(tmp_path):
    head = f'base = "{PAPER}"\ncount = 60\nseed = 11\n'
    refused = accepted = 0
    for s in samples(load_study(_study(tmp_path, LOSSES, head=head))):
        g = s.scenario_data["graph"]
        A, b = np.array(g["adjacency"]), np.array(g["pinning"])
        sw = g.get("switches", [])
        assert [x["time"] for x in sw] == sorted(x["time"] for x in sw)
        k = 1
        while f"graph.loss[{k}].time" in s.params:
            i, j = s.params[f"graph.loss[{k}].follower"], s.params[f"graph.loss[{k}].neighbour"]
            t, back = s.params[f"graph.loss[{k}].time"], s.params[f"graph.loss[{k}].recovery"]
            w = b[i - 1] if j == 0 else A[i - 1, j - 1]
            assert w > 0 and 2.0 <= t <= 12.0 and 1.0 <= back - t <= 10.0  # an existing link
            mine = [x for x in sw if (x["follower"], x["neighbour"]) == (i, j)]
            want = [(t, 0.0)] + ([(back, w)] if back < 20.0 else [])  # horizon 20 s
            assert [(x["time"], x["weight"]) for x in mine] == want
            k += 1
        assert 1 <= k - 1 <= 3
        # the loader refuses exactly the samples where some topology cuts a follower off
        cut = not all(_reachable(At, bt).all() for At, bt in _topologies(A, b, sw))
        assert (s.scenario is None) == cut, s.reason
        if cut:
            assert "graph.switches" in s.reason
            refused += 1
        else:
            accepted += 1
    assert refused and accepted  # both kinds occur with these settings


def test_reachable_losses_keep_assumption_1_in_every_topology(tmp_path):
    """``reachable = true``: every sample passes the loader and every topology keeps every
    follower reachable (the test's own fixed point); the losses are links of the graph, at
    most ``count`` of them; without the key the same study has samples the loader refuses."""
    head = f'base = "{PAPER}"\ncount = 60\nseed = 11\n'
    lost_total = 0
    for s in samples(load_study(_study(tmp_path, LOSSES + "reachable = true\n", head=head))):
        assert s.scenario is not None, s.reason
        g = s.scenario_data["graph"]
        A, b = np.array(g["adjacency"]), np.array(g["pinning"])
        sw = g.get("switches", [])
        assert all(_reachable(At, bt).all() for At, bt in _topologies(A, b, sw))
        lost = {(x["follower"], x["neighbour"]) for x in sw if x["weight"] == 0.0}
        assert all((b[i - 1] if j == 0 else A[i - 1, j - 1]) > 0 for i, j in lost)
        assert len(lost) <= 3
        lost_total += len(lost)
    assert lost_total >= 60  # most samples lose links
    plain = samples(load_study(_study(tmp_path, LOSSES, head=head)))
    assert any(s.scenario is None for s in plain)


def test_tail_switch_count_and_last_switch_follow_the_drawn_losses(tmp_path):
    """The row's ``tail_switches`` and ``last_switch_t`` from the drawn loss and recovery
    times (the sampler's parameters, not the scenario's switch list the function reads):
    tail window [10, 20] s of the 20-s horizon."""
    import pandas as pd

    from sweep.measures import topology_in_tail

    head = f'base = "{PAPER}"\ncount = 30\nseed = 11\n'
    frame = pd.DataFrame({"t": np.linspace(0.0, 20.0, 201)})
    seen = set()
    for s in samples(load_study(_study(tmp_path, LOSSES, head=head))):
        if s.scenario is None:
            continue
        times, k = set(), 1
        while f"graph.loss[{k}].time" in s.params:
            times.add(s.params[f"graph.loss[{k}].time"])
            back = s.params[f"graph.loss[{k}].recovery"]
            times |= {back} if back < 20.0 else set()
            k += 1
        got = topology_in_tail(s.scenario, frame, 0.5)
        assert got["tail_switches"] == sum(10.0 <= t <= 20.0 for t in times)
        assert got["last_switch_t"] == max(times)
        seen.add(got["tail_switches"] > 0)
    assert seen == {True, False}  # both kinds occur
    fixed = topology_in_tail(load_scenario(PAPER), frame, 0.5)
    assert fixed["tail_switches"] == 0 and math.isnan(fixed["last_switch_t"])
