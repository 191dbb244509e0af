"""Study inputs that would escape: names that leave out/, files that are not regular
files, distributions whose bounds overflow, tables nested without end. Each is one line
naming the field and the fix, a non-zero exit, and no file written.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import ROOT

from core.errors import run_cli
from sweep.__main__ import main
from sweep.study import MAX_DEPTH

PAPER = (ROOT / "scenarios" / "paper.toml").as_posix()
HEAD = f'base = "{PAPER}"\ncount = 3\nseed = 1\n'


def _error(argv: list[str], capsys) -> str:
    """Run ``python -m sweep`` in-process: exit status 2 and one line on stderr."""
    assert run_cli(main, argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("text", ['name = ".."\n', 'name = "../up"\n', 'name = ".hidden"\n'])
def test_study_name_that_leaves_out_is_refused_and_nothing_is_written(tmp_path, capsys, text):
    (tmp_path / "s.toml").write_text(text + HEAD)
    err = _error(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")], capsys)
    assert ": name: " in err and "not a plain name" in err and "not starting with '.'" in err
    assert _files(tmp_path) == ["s.toml"]


def test_file_named_dot_dot_dot_toml_gets_no_name_that_leaves_out(tmp_path, capsys):
    """``...toml`` has the stem ``..``: as a default name it would write above out/."""
    (tmp_path / "...toml").write_text(HEAD)
    err = _error(["run", str(tmp_path / "...toml"), "--out", str(tmp_path / "out")], capsys)
    assert ": name: '..' is not a plain name" in err
    assert _files(tmp_path) == ["...toml"]


def _cli(path: Path | str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m sweep run`` in a subprocess: a file read that blocks or never ends
    is a timeout here, not a hung test run."""
    pythonpath = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": pythonpath}
    return subprocess.run(
        [sys.executable, "-m", "sweep", "run", str(path), "--out", str(cwd / "out")],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_study_that_is_not_a_regular_file_is_refused_unread(tmp_path, kind):
    if kind == "fifo":
        path: Path | str = tmp_path / "s.toml"
        os.mkfifo(path)
        what = "named pipe (FIFO)"
    else:
        path, what = "/dev/zero", "character device"
    proc = _cli(path, tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert f"(file): is a {what}, not a regular file" in proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_base_that_is_not_a_regular_file_says_so(tmp_path, capsys, kind):
    base = tmp_path / "base.toml"
    os.mkfifo(base) if kind == "fifo" else base.mkdir()
    (tmp_path / "s.toml").write_text('base = "base.toml"\ncount = 3\nseed = 1\n')
    err = _error(["samples", str(tmp_path / "s.toml")], capsys)
    assert ": base: base.toml is a " in err and "not a regular file" in err
    assert "does not exist" not in err


OVERFLOW = [
    ('"controller.k1" = { uniform = [-1.7e308, 1.7e308] }', "uniform", "hi - lo overflows"),
    (
        '"controller.k1" = { normal = [0, 1e-300], truncate = [1e300, 1.7e308] }',
        "truncate",
        "(bound - mean) / std overflows",
    ),
    (
        '"controller.k1" = { normal = [-1.7e308, 1.0], truncate = [0, 1.7e308] }',
        "truncate",
        "(bound - mean) / std overflows",
    ),
]


@pytest.mark.parametrize(
    ("spec", "key", "problem"), OVERFLOW, ids=["uniform", "tiny-std", "far-mean"]
)
def test_distribution_whose_bounds_overflow_is_refused_at_load(
    tmp_path, capsys, spec, key, problem
):
    (tmp_path / "s.toml").write_text(HEAD + "[params]\n" + spec + "\n")
    err = _error(["samples", str(tmp_path / "s.toml")], capsys)
    assert f'params."controller.k1".{key}: {problem}' in err and "(expected " in err


@pytest.mark.parametrize("depth", [MAX_DEPTH, 495])
def test_set_nested_deeper_than_documented_is_refused_in_one_line(tmp_path, capsys, depth):
    """``[set.a.a...]``: ``depth`` tables below the top, a value inside the last one."""
    header = "[" + ".".join(["set"] + ["a"] * (depth - 1)) + "]\nx = 1\n"
    (tmp_path / "s.toml").write_text(HEAD + header)
    err = _error(["samples", str(tmp_path / "s.toml")], capsys)
    if depth <= MAX_DEPTH:  # within the limit: refused for what it says, not its depth
        assert "nests" not in err
    else:
        assert f"(file): nests tables or arrays more than {MAX_DEPTH} deep" in err


def test_documented_depth_is_the_code_s():
    text = (ROOT / "docs" / "studies.md").read_text()
    assert f"{MAX_DEPTH} levels" in text
