"""Figures, report files and the command line of ``verify`` (synthetic data, no simulation)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import PAPER

from core.errors import run_cli
from verify import figures as F
from verify.__main__ import main
from verify.report import Verification, ablation_statement, render_markdown, write_report
from verify.synthetic import synthetic_trajectory
from verify.table import bounds_table

C0 = np.array([[1.0, 1.0], [2.0, 2.0]])


@pytest.fixture(scope="module")
def data(paper_scenario):
    sc = paper_scenario
    df = synthetic_trajectory(step=0.1)
    ab = synthetic_trajectory(step=0.1, track_rate=1.0)
    return sc, df, ab


def _is_png(p: Path) -> bool:
    return p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_snapshot_figures_png_and_pdf(tmp_path, data):
    _, df, _ = data
    files = F.formation_snapshots(df, C0, tmp_path, times=(0.0, 5.0))
    names = {p.name for p in files}
    assert {"fig03_formation_t0.png", "fig03_formation_t0.pdf", "fig04_formation_t5.png"} <= names
    assert "fig03-10_formation_overview.png" in names
    for p in files:
        assert p.stat().st_size > 1000
        if p.suffix == ".png":
            assert _is_png(p)
        else:
            assert p.read_bytes()[:5] == b"%PDF-"
    assert not list(tmp_path.glob(".*tmp"))  # atomic writes leave no temporary files


def test_error_and_ablation_figures(tmp_path, data):
    _, df, ab = data
    files = F.estimation_errors(df, tmp_path) + F.tracking_errors(df, tmp_path)
    files += F.ablation_comparison(df, ab, tmp_path)
    stems = {p.stem for p in files}
    assert {"fig11_estimation_errors", "fig12_tracking_errors", "fig13_ablation"} <= stems
    assert all(_is_png(p) for p in files if p.suffix == ".png")


@pytest.mark.skipif(importlib.util.find_spec("PIL") is None, reason="Pillow not installed")
def test_animation_gif(tmp_path, data):
    _, df, _ = data
    path, note = F.animation(df, C0, tmp_path, frames=4)
    assert path is not None and path.read_bytes()[:6] in (b"GIF89a", b"GIF87a")


def test_report_and_bounds_csv(tmp_path, data):
    sc, df, ab = data
    tb = bounds_table(sc, df, ablation=ab)
    v = Verification(scenario=sc, table=tb, ablation_summary=ablation_statement(tb))
    rpath, bpath = write_report(v, tmp_path)
    text = rpath.read_text()
    assert "| claim | agent | component | kind | bound | observed | ratio | holds |" in text
    assert "The ablation converges more slowly" in text
    back = pd.read_csv(bpath, keep_default_na=False)
    assert len(back) == len(tb)
    # an empty cell is a bound the derivation gives but this run cannot compute
    got = back["bound"].replace("", "nan").astype(float)
    np.testing.assert_allclose(got, tb["bound"], rtol=1e-12)
    assert "Verdict (default): **PASS**" in text


def test_ablation_statement_says_plainly_when_not_slower(data):
    sc, df, _ = data
    faster = synthetic_trajectory(step=0.1, track_rate=4.0)  # the "ablation" converges faster
    tb = bounds_table(sc, df, ablation=faster)
    assert "does NOT converge more slowly" in ablation_statement(tb)


def test_strict_verdict_reports_failed_paper_claims(data):
    sc, df, _ = data
    df = df.copy()
    df["chi2_1"] += 100.0  # far above χ̄
    tb = bounds_table(sc, df)
    text = render_markdown(Verification(scenario=sc, table=tb), strict=True)
    assert "Verdict (strict): **FAIL**" in text
    assert "do not hold on these numbers" in text


def test_cli_missing_scenario_is_one_line_exit_2(capsys):
    code = run_cli(main, ["check", "no/such/scenario.toml"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "does not exist" in err


def test_cli_bad_override_is_one_line_exit_2(capsys):
    code = run_cli(main, ["check", str(PAPER), "--set", "no-equals-sign"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "KEY=VALUE" in err


def test_cli_bad_delta_is_one_line_exit_2(capsys):
    code = run_cli(main, ["check", str(PAPER), "--delta", "1.5"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "lemma1_delta" in err


@pytest.mark.parametrize(
    "argv", [["frobnicate"], ["check", str(PAPER), "--tail", "half"], ["check", "--nope"]]
)
def test_cli_bad_arguments_are_one_line_exit_2(capsys, argv):
    # argparse errors go through core.errors.CliParser: no usage dump, one line
    code = run_cli(main, argv)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "see --help" in err
