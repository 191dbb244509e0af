"""The topology study on the per-agent driver (``python -m sweep.topologies``).

A few samples of ``studies/topologies.toml`` run on one kernel library compiled for the
first; an integration that stops early is a row ``incomplete`` with where it stopped and
why (named in the report), never a crash of the study.
"""

from __future__ import annotations

import dataclasses

import pytest

from generated import agents
from generated.solvers import Status
from sweep import topologies

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
