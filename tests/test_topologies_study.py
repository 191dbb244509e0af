"""The topology study (``studies/topologies.toml``) through ``python -m sweep run``.

A few samples run on method ``native`` (the per-agent engine): one kernel library for
graphs of different sizes, verdicts and coverage per sample, resumable; the paper's λ1
kept, Theorem 1 per topology a column (``theorem1 = "measured"``). An integration that
stops early is a ``failed`` row with where CVODE stood, named in the report.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import PAPER

from core.graph import pinned_laplacian
from core.scenario import load_scenario
from generated import agents, api
from generated.schedule import output_grid
from generated.values import CodegenSettings
from sweep import worker
from sweep.report import stop_text
from sweep.run import run_study
from sweep.sampler import make_sample
from sweep.study import load_study
from sweep.switched_gains import base_graph_gains

STUDY = "studies/topologies.toml"
#: sample 0: acyclic, N = 7, no losses; 1: refused (a loss cuts a follower off); 3: cyclic,
#: N = 8, two links lost and restored; 11: cyclic, N = 8, no losses
IDS = [0, 1, 3]


@pytest.fixture(scope="module")
def out(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("topologies")
    run_study(STUDY, out_root=root, ids=IDS, workers=1)
    return root / "topologies"


def _table(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "results.parquet").set_index("id")


def _w_dense(A: np.ndarray, b: np.ndarray) -> float:
    """Lemma 3's w with the paper's z, dense: λ_min(Z^-1/2 (L̄ᵀZ + ZL̄) Z^-1/2)."""
    L = pinned_laplacian(A, b).toarray()
    z = np.linalg.solve(L.T, np.ones(len(L)))
    S = L.T * z + (L.T * z).T  # L̄ᵀZ + ZL̄
    d = 1 / np.sqrt(z)
    return float(np.linalg.eigvalsh(d[:, None] * S * d[None, :]).min())


def test_one_library_verdicts_and_coverage_per_sample(out):
    t = _table(out)
    assert list(t.index) == IDS
    assert t.loc[1, "status"].startswith("refused: ") and "Assumption 1" in t.loc[1, "status"]
    ok = t[t["status"] == "ok"]
    assert len(ok) == 2 and ok["param:graph.N"].nunique() == 2  # graphs of different sizes
    assert ok["library"].nunique() == 1  # one kernel library for both graphs
    assert list(ok["cyclic"]) == [False, True]
    assert (ok["n_guaranteed"] > 0).all() and ok["guaranteed_held"].notna().all()
    for k in ok.index:  # a coverage column per follower of the sample, and no other
        N = int(ok.loc[k, "param:graph.N"])
        cov = [c for c in ok.columns if c.startswith("covered:") and pd.notna(ok.loc[k, c])]
        assert sorted(cov) == sorted(f"covered:{i}" for i in range(1, N + 1))
    assert (ok["t_reached"] == 20.0).all() and ok["stop_state"].eq("").all()
    assert ok["t_stop"].isna().all()
    report = (out / "report.md").read_text()
    assert "| kernel libraries (per-agent engine) | 1 (" in report
    assert "| Theorem 1 shown on every topology with the paper's z |" in report


def test_theorem1_per_topology_against_a_dense_lemma3(out):
    """Truth: Lemma 3's w of every topology by a dense eigenvalue computation."""
    t = _table(out)
    study = load_study(STUDY)
    for k in (0, 3):
        sc = make_sample(study, k).scenario
        tops = sc.graph.topologies()
        w = min(_w_dense(top.adjacency, top.pinning) for top in tops)
        assert t.loc[k, "topologies"] == len(tops) == (1 if k == 0 else 5)
        assert t.loc[k, "w_min"] == pytest.approx(w, rel=1e-9)
        o = sc.observer
        assert t.loc[k, "theorem1"] == bool(o.lambda1 * w > o.lambda_bar1)


def test_steps_equal_the_engine_called_directly(out):
    """The row's integrator steps are those of ``agents.run`` on the sample with the
    paper's gains: the study keeps them (no per-sample synthesis of λ1)."""
    sample = make_sample(load_study(STUDY), 3)
    sc = sample.scenario
    gains = base_graph_gains(sc, "gains")
    assert gains.lambda1 == load_scenario(PAPER).observer.lambda1  # the paper's, not synthesized
    settings = api.integrator_settings(sc, "native", api.resolve_codegen(sc.N))
    libs, model = agents.build_models(sc, gains, api.resolve_codegen(sc.N))
    tr = agents.run(
        [lib.path for lib in libs],
        agents.problem(sc, gains, model),
        agents.initial_state(sc),
        output_grid(sc.integration.horizon, sc.integration.output_step),
        settings,
        breakpoints=sc.breakpoints(),
    )
    assert tr.complete
    assert _table(out).loc[3, "steps"] == tr.stats["steps"]


def test_graphs_of_one_n_share_one_structure_with_the_graph_as_data():
    """Samples 3 and 11 (N = 8, other links, two losses and none): one dense structure."""
    from symbolic.parameters import structure_key

    study = load_study(STUDY)
    assert worker.engine(study)["dense"]
    keys = []
    for k in (3, 11):
        sc = make_sample(study, k).scenario
        gains = base_graph_gains(sc, "gains")
        keys.append((structure_key(sc, gains), structure_key(sc, gains, dense=True)))
    assert keys[0][0] != keys[1][0] and keys[0][1] == keys[1][1]


def test_the_graph_as_data_gives_the_graphs_own_frame_and_checks():
    """Sample 3 (N = 8, two links lost and restored) on the study's loop with the graph as
    data, its frame from the compiled verification outputs, equals the sample's own loop's
    frame (CasADi's virtual machine) and bounds table, bit for bit."""
    from verify import lyapunov, pipeline

    sc = make_sample(load_study(STUDY), 3).scenario
    gains = base_graph_gains(sc, "gains")
    codegen = api.resolve_codegen(sc.N)
    own = api.build(sc, gains, "native", codegen)
    dense = api.build(sc, gains, "native", codegen, dense_graph=True)
    assert own.closed_loop.parametric.structure_key != dense.closed_loop.parametric.structure_key
    traj = api.simulate(own, sc, api.integrator_settings(sc, "native", codegen))
    frames = [worker._frame(dense, sc, traj), api.trajectory_frame(own, sc, traj)]
    cl = dense.closed_loop
    assert lyapunov.fast_functions(cl, lyapunov.run_digest(cl.p0, traj.t, traj.x)).compiled
    pd.testing.assert_frame_equal(*frames, check_exact=True)
    tables = [
        pipeline.verify_run(
            pipeline.Run(
                sc, frames[0], traj.x, {}, Path("x"), gains=gains, closed_loop=b.closed_loop
            )
        ).table
        for b in (dense, own)
    ]
    pd.testing.assert_frame_equal(*tables, check_exact=True)


def test_a_rerun_runs_only_the_missing_samples(out):
    before = _table(out)
    run_study(STUDY, out_root=out.parent, ids=[*IDS, 11], workers=1)
    after = _table(out)
    assert list(after.index) == [*IDS, 11] and after.loc[11, "status"] == "ok"
    for k in IDS:  # the recorded rows are kept as they were
        assert after.loc[k, "finished_utc"] == before.loc[k, "finished_utc"]
        assert after.loc[k, "wall_s"] == before.loc[k, "wall_s"] or np.isnan(
            before.loc[k, "wall_s"]
        )


def test_a_run_that_gives_up_reports_where_cvode_stood(tmp_path):
    """A real stop (too few steps allowed): the row and the report name CVODE's last state.

    Truth: a second run of the same sample, to t_stop, with the steps it needs.
    """
    text = Path(STUDY).read_text()
    fade = '"graph.link_fade" = 0.0\n'  # the study's [set] (the per-agent engine switches raw)
    base = 'base = "../scenarios/paper.toml"'
    assert text.count(fade) == 1 and text.count(base) == 1
    text = text.replace(base, f'base = "{PAPER.as_posix()}"')
    path = tmp_path / "few-steps.toml"
    path.write_text(text.replace(fade, fade + '"integration.max_steps" = 300\n'))
    row = worker.run_sample(str(path), 0, str(tmp_path / "out"))
    assert row["status"].startswith("failed: IntegrationError: ")
    assert row["t_reached"] < row["t_stop"] < row["t_reached"] + 0.01  # the output step
    sc = make_sample(load_study(str(path)), 0).scenario
    gains = base_graph_gains(sc, "gains")
    libs, model = agents.build_models(sc, gains, api.resolve_codegen(sc.N))
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
    assert not sc.graph.switches and np.isnan(row["switch_before_stop"])  # sample 0: none
    assert f"the largest state is {row['stop_state']} = " in row["status"]  # the error says it
    note = stop_text(row)  # the report's line adds the rows before and the last switch
    assert (
        note
        == f" (at most {row['rows_abs']:.3g} in the output rows before; no topology switch before)"
    )
    full = stop_text({**row, "status": "failed: cut"})
    assert f"the largest state there {row['stop_state']} = " in full and full.endswith(note[2:])


def test_the_report_times_a_stop_from_the_last_switch():
    row = dict(t_stop=6.3737, stop_state="q10_1", stop_abs=6.88e4, rows_abs=870.0)
    text = stop_text({**row, "switch_before_stop": 6.3729})
    assert "the largest state there q10_1 = 6.88e+04 in magnitude, at most 870 in the" in text
    assert "; 0.8 ms after the last topology switch)" in text
    assert stop_text({"t_stop": np.nan}) == "" == stop_text({})
