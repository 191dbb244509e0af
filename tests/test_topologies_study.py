"""The topology study on the per-agent driver (``python -m sweep.topologies``).

A few samples of ``studies/topologies.toml`` run on one kernel library compiled for the
first; an integration that stops early is a row ``incomplete`` with where it stopped and
why (named in the report), never a crash of the study.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from generated import agents, api
from generated.values import CodegenSettings, Status
from sweep import topologies
from sweep.sampler import make_sample
from sweep.study import load_study

STUDY = "studies/topologies.toml"


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    root = str(tmp_path_factory.mktemp("topologies"))
    return topologies.run_study(STUDY, 4, 1, root)


def test_one_library_for_every_graph(rows):
    ran = [r for r in rows if r["status"] != "refused"]
    assert len(ran) >= 2 and len({r["N"] for r in ran}) >= 2  # graphs of different sizes
    assert len({r["library"] for r in ran}) == 1
    assert [r["compiled"] for r in ran] == [True] + [False] * (len(ran) - 1)
    assert all(r["status"] == "complete" and r["t_reached"] == 20.0 for r in ran)


def test_a_run_that_gives_up_reports_where_cvode_stood(tmp_path):
    """A real stop (too few steps allowed): the row and the report name CVODE's last state.

    Truth: a second run of the same sample, to t_stop, with the steps it needs.
    """
    study = Path(STUDY).read_text().replace("count = 1000", "count = 1")
    base = Path("scenarios/paper.toml").resolve().as_posix()
    study = study.replace('base = "../scenarios/paper.toml"', f'base = "{base}"')
    path = tmp_path / "few-steps.toml"
    fade = '"graph.link_fade" = 0.0\n'  # the study's [set] (the per-agent driver switches raw)
    assert study.count(fade) == 1
    path.write_text(study.replace(fade, fade + '"integration.max_steps" = 1000\n'))
    (row,) = topologies.run_study(str(path), 1, 1, None)
    assert row["status"] == "incomplete"
    assert row["t_reached"] < row["t_stop"] < row["t_reached"] + 0.01  # the output step
    sample = make_sample(load_study(str(path)), 0)
    sc = sample.scenario
    gains, _, _ = topologies.sample_gains(api.scenario_gains(sc, "gains"), sc)
    libs, model = agents.build_models(sc, gains, CodegenSettings())
    settings = api.integrator_settings(sc, "native", CodegenSettings())
    tr = agents.run(
        [lib.path for lib in libs],
        agents.problem(sc, gains, model),
        agents.initial_state(sc),
        np.array([0.0, row["t_stop"]]),
        dataclasses.replace(settings, max_steps=200_000),
    )
    lay = agents.make_layout(sc.m, sc.n, sc.N, False)
    k = int(np.argmax(np.abs(tr.x[-1])))
    assert row["stop_state"] == lay.name_of(k)
    assert row["stop_abs"] == pytest.approx(abs(tr.x[-1, k]), rel=1e-3)
    assert row["rows_abs"] == np.abs(agents.initial_state(sc)).max()  # the only row: x(0)
    assert row["stop_abs"] > 2 * row["rows_abs"]  # so x(0) in its place would fail above
    text = topologies.report([row], 1.0, str(path))
    assert f"the largest state is {row['stop_state']} = " in text
    assert "(complete runs): no complete run" in text
    if sc.graph.switches:  # sample 0 has none: the report says so
        assert row["switch_before_stop"] <= row["t_stop"]
    else:
        assert np.isnan(row["switch_before_stop"]) and "no topology switch before" in text


def test_an_integration_that_stops_early_is_an_incomplete_row(rows, monkeypatch, tmp_path):
    real = agents.run

    def stops_at_5s(*args, **kwargs):
        tr = real(*args, **kwargs)
        k = int((tr.t <= 5.0).sum())
        return dataclasses.replace(
            tr, t=tr.t[:k], x=tr.x[:k], status=Status.STEP_LIMIT, t_reached=5.0, message="x"
        )

    monkeypatch.setattr(agents, "run", stops_at_5s)
    again = topologies.run_study(STUDY, 2, 1, str(tmp_path))
    bad = [r for r in again if r["status"] == "incomplete"]
    assert bad and all(r["t_reached"] == 5.0 and r["message"] == "x" for r in bad)
    text = topologies.report(again, 1.0, STUDY)
    assert text.splitlines()[2].startswith("measured ")  # date, commit and machine
    assert (
        f"incomplete: sample {bad[0]['sample']} (N = {bad[0]['N']}) stopped at t = 5 s: x" in text
    )


def test_the_report_times_a_stop_from_the_last_switch():
    row = dict(sample=15, N=18, cyclic=True, losses=2, theorem1=False, status="incomplete")
    row.update(t_reached=6.37, message="TOO_MUCH_WORK", t_stop=6.3737, stop_state="q10_1")
    row.update(stop_abs=6.88e4, rows_abs=870.0, switch_before_stop=6.3729, simulate_s=1.0)
    row.update(library="k", compiled=False)
    text = topologies.report([row], 1.0, STUDY)
    assert "the largest state is q10_1 = 6.88e+04 in magnitude (at most 870 in the output" in text
    assert "; 0.8 ms after the last topology switch)" in text
