"""The study report from a results table: the fault scatter data, the per-type table, the
figures and the rerun command of a sample whose guaranteed check fails.

Independent truths: the drawn values of studies/faults.toml's samples (the sampler, not
the report) placed in a hand-made results table, counts and medians recomputed here, and
the rerun command executed: it must write the scenario file it then names.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
from helpers import ROOT

from sweep.report import fault_points, write_report
from sweep.results import commit_rows
from sweep.sampler import samples
from sweep.study import load_study
from sweep.worker import param_columns

FAULTS = ROOT / "studies" / "faults.toml"


def _table(tmp_path):
    """Rows for samples 0..11 of faults.toml: drawn values real, results made up; id 5 fails
    a guaranteed row, id 7 is failed."""
    rows = []
    for s in samples(load_study(FAULTS), ids=range(12)):
        row = {"id": s.id, "seed": str(s.seed), "name": s.scenario_data["name"]}
        row.update(param_columns(s), status="ok", tail_max_et=1e-3 * (s.id + 1))
        row.update(
            guaranteed_held=s.id != 5, guaranteed_failed="T2 bound (follower 2)" * (s.id == 5)
        )
        row.update(
            consistency_held=True, n_consistency=1, n_guaranteed=3, **{"t2_entry:1": 2.0 + s.id}
        )
        rows.append(row)
    rows[7]["status"] = "failed: IntegrationError: gave up"
    path = tmp_path / "faults" / "results.parquet"
    path.parent.mkdir()
    info = {"date": "2026-12-01T00:00:00+00:00", "command": "test", "study": str(FAULTS)}
    return commit_rows(path, pd.DataFrame(), rows, info), path


def test_fault_points_are_the_drawn_faults_of_the_ok_samples(tmp_path):
    table, _ = _table(tmp_path)
    pts = fault_points(table).set_index("id")
    truth = {s.id: s.params for s in samples(load_study(FAULTS), ids=range(12))}
    assert sorted(pts.index) == [k for k in range(12) if k != 7]  # one fault each, failed left out
    for k, p in pts.iterrows():
        assert p["type"] == truth[k]["faults[1].type"] and p["onset"] == truth[k]["faults[1].onset"]
        if p["type"] == "bias":
            assert np.isnan(p["severity"])
            assert p["bias"] == np.hypot(*truth[k]["faults[1].amplitude"])
        else:
            assert p["severity"] == truth[k]["faults[1].severity"] and np.isnan(p["bias"])
        assert p["tail_max_et"] == 1e-3 * (k + 1)


def test_report_has_the_figures_the_type_table_and_a_working_rerun_command(tmp_path):
    table, path = _table(tmp_path)
    text = write_report(path).read_text()
    for fig in ("tail_error", "theorem2_entry", "error_vs_severity", "error_vs_onset"):
        data = (path.parent / "figures" / f"{fig}.png").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and f"figures/{fig}.png" in text
    ok = table[table["status"] == "ok"]
    for kind, grp in ok.groupby("param:faults[1].type"):
        med = np.median(grp["tail_max_et"])
        assert f"| {kind} | {len(grp)} | {med:.4g} |" in text
    line = next(x for x in text.splitlines() if x.startswith("- id 5 "))
    assert "T2 bound (follower 2)" in line
    write, _, sim = re.search(r"`(.+)`", line).group(1).partition(" && ")
    argv = shlex.split(write)
    assert argv[:3] == ["python", "-m", "sweep"]
    proc = subprocess.run([sys.executable, *argv[1:]], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    scenario = sim.removeprefix("make sim SCENARIO=")
    written = tomllib.loads(Path(scenario).read_text())
    assert written["name"] == "faults-0005"
    assert "- id 7: failed: IntegrationError" in text


def test_tail_error_is_split_by_a_topology_switch_in_the_tail_window():
    """Medians of the two groups recomputed here; no split when no tail saw a switch, and
    none for rows written without the column."""
    from sweep.report import tail_split_lines

    ok = pd.DataFrame(
        {"tail_max_et": [1.0, 2.0, 4.0, 100.0, 300.0], "tail_switches": [0, 0, 0, 1, 2]}
    )
    lines = tail_split_lines(ok)
    assert len(lines) == 2
    assert "one fixed graph (3 samples) | 2 |" in lines[0]
    assert "a topology switch (2 samples) | 200 |" in lines[1]
    assert tail_split_lines(ok.assign(tail_switches=0)) == []
    assert tail_split_lines(ok.drop(columns="tail_switches")) == []


def test_step_lines_count_each_kind_of_step_pair():
    """3 + 2 pairs, 1 late, 1 undefined: 3 back in time; no line for a study without steps."""
    from sweep.report import step_lines

    ok = pd.DataFrame(
        {"step_pairs": [3, 2], "step_pairs_late": [1, 0], "step_pairs_undefined": [0, 1]}
    )
    (line,) = step_lines(ok)
    assert "within 0.05 of the slot within 2 s | 3 of 5 (1 late; 1 undefined" in line
    assert step_lines(ok.assign(step_pairs=0)) == []
    assert step_lines(pd.DataFrame({"tail_max_et": [1.0]})) == []


def test_link_lines_count_pairs_and_the_ratio_to_the_no_loss_runs():
    import pandas as pd

    from sweep.report import link_lines

    ok = pd.DataFrame(
        {
            "id": [3, 7],
            "switch_pairs": [10, 6],
            "switch_pairs_late": [1, 0],
            "switch_pairs_undefined": [2, 1],
            "switch_pairs_out_before": [0, 1],
            "switch_recovery_s": [1.5, float("inf")],
            "switch_pairs_late_nolosses": [2, 0],
            "switch_pairs_undefined_nolosses": [2, 1],
            "peak_u_late": [300.0, 100.0],
            "peak_u_late_nolosses": [100.0, 100.0],
        }
    )
    text = "\n".join(link_lines(ok))
    assert "| 12 of 16 (1 late; 3 undefined" in text and "1 already out" in text
    assert "11 of 16 back (2 late; 3 undefined)" in text
    assert "median 2, largest 3 (sample 3); 1 of 2 within 2x" in text
    assert "| inf |" in text  # a follower that never came back
    assert link_lines(ok.assign(switch_pairs=0)) == []


def test_given_link_lines_are_the_link_lines_of_the_base_gains_runs():
    """compare_gains: the given: columns of the rows whose given run is ok, marked so."""
    from sweep.coverage import GIVEN
    from sweep.report import given_link_lines, link_lines

    cols = {
        "switch_pairs": [10, 6, 4],
        "switch_pairs_late": [1, 0, 4],
        "switch_pairs_undefined": [2, 1, 0],
        "switch_pairs_out_before": [0, 1, 0],
        "switch_recovery_s": [1.5, 3.0, 9.0],
        "switch_pairs_late_nolosses": [2, 0, 4],
        "switch_pairs_undefined_nolosses": [2, 1, 0],
        "peak_u_late": [300.0, 100.0, 900.0],
        "peak_u_late_nolosses": [100.0, 100.0, 100.0],
    }
    table = pd.DataFrame(
        {
            "id": [3, 7, 8],
            "status": ["ok"] * 3,
            **{k: [0, 0, 0] for k in cols},
            f"{GIVEN}status": ["ok", "ok", "failed: x"],  # the third is left out
            **{f"{GIVEN}{k}": v for k, v in cols.items()},
        }
    )
    lines = given_link_lines(table)
    plain = link_lines(pd.DataFrame({"id": [3, 7], **{k: v[:2] for k, v in cols.items()}}))
    assert len(lines) == len(plain) == 4
    for a, b in zip(lines, plain, strict=True):
        assert a == "| with the base scenario's own gains: " + b.removeprefix("| ")
    assert "| 12 of 16 (1 late; 3 undefined" in lines[0]
    assert given_link_lines(table.drop(columns=f"{GIVEN}status")) == []


def test_out_lines_say_what_keeps_the_pairs_out():
    """Two samples (N = 6 and 13): 3 + 1 pairs out, with and without the losses."""
    from sweep.report import out_lines

    ok = pd.DataFrame(
        {
            "param:graph.N": [6, 13],
            "switch_pairs": [10, 20],
            "switch_pairs_late": [2, 1],
            "switch_pairs_undefined": [1, 0],
            "switch_out_within": [2, 1],
            "switch_out_own": [1, 0],
            "switch_out_observer": [3, 0],
            "switch_out_worst_max": [0.07, 0.2],
            "switch_out_observer_max": [0.069, 0.01],
            "switch_out_controller_max": [0.002, 0.19],
            "switch_pairs_late_nolosses": [2, 0],
            "switch_pairs_undefined_nolosses": [0, 0],
            "switch_out_within_nolosses": [2, 0],
            "switch_out_observer_nolosses": [2, 0],
        }
    )
    mine, nolosses, by_n = out_lines(ok, 30)
    assert "of the 4 pairs not back in time | 3 within the level for the whole 2 s" in mine
    assert "1 whose follower's own links switched; 3 with the observer's part" in mine
    assert "at most 0.2 (observer's part up to 0.069, controller's up to 0.19)" in mine
    assert "of the 2 pairs not back without losses | 2 within the level" in nolosses
    assert "2 with the observer's part above" in nolosses
    assert by_n == "| pairs not back in time by N (of 30) | N = 6–10: 3 of 10; N = 11–13: 1 of 20 |"
    *_, one = out_lines(ok.assign(**{"param:graph.N": [6, 11]}), 30)
    assert one.endswith("| N = 6–10: 3 of 10; N = 11: 1 of 20 |")
    assert out_lines(ok.drop(columns="switch_out_within"), 30) == []
