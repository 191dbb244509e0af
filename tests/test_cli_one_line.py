"""Every command line refuses a bad flag or value in ONE line, exit 2, before any work.

The commands run in this process through :func:`core.errors.run_cli`; where a value would
start work on the old code (a compile, a simulation) that work is replaced by a stand-in
that fails the test if reached. ``synthesis certify`` reads its file only when it is a
regular file of bounded size and depth: ``/dev/zero`` and a FIFO are refused unread.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest
from helpers import PAPER, ROOT

from benchmarks import agents, bench, links, lone, precision, remedies, steps, study
from benchmarks import search as bench_search
from console import __main__ as console_main
from console import sessions as console_sessions
from core.errors import run_cli
from generated import __main__ as generated_main
from search import __main__ as search_main
from synthesis import cli as synthesis_cli
from verify import __main__ as verify_main

P = str(PAPER)
CASES = [
    (generated_main.main, ["sim", P, "--method", "bogus"], "--method"),
    (generated_main.main, ["sim", P, "--fixed-tol", "-1"], "--fixed-tol"),
    (generated_main.main, ["sim", P, "--compiler", ""], "--compiler"),
    (generated_main.main, ["sim"], "scenario"),
    (generated_main.main, ["bogus"], "invalid choice"),
    (
        generated_main.main,
        ["sim", P, "--set", "options.ablation=true", "--variant", ""],
        "--variant",
    ),
    (verify_main.main, ["check", P, "--bogus"], "--bogus"),
    (verify_main.main, ["report", P, "--tail", "x"], "--tail"),
    (synthesis_cli.main, ["certify"], "gains"),
    (
        synthesis_cli.main,
        ["synth", P, "--set", "options.ablation=true", "--variant", "a b"],
        "--variant",
    ),
    (console_main.main, ["serve", P, "--port", "99999"], "--port"),
    (console_main.main, ["serve", P, "--port", "0"], "--port"),
    (console_main.main, ["serve", P, "--rise", "nan"], "--rise"),
    (console_main.main, ["serve", P, "--bias-max", "inf"], "--bias-max"),
    (console_sessions.main, ["--sessions", "0"], "--sessions"),
    (console_sessions.main, ["--rise", "-1"], "--rise"),
    (console_sessions.main, ["--bogus"], "--bogus"),
    (search_main.main, ["run", "x.toml", "--workers", "0"], "--workers"),
    (search_main.main, ["run", "x.toml", "--budget", "-3"], "--budget"),
    (bench.main, ["--runs", "0"], "--runs"),
    (bench.main, ["--horizon", "-1"], "--horizon"),
    (study.main, ["--samples", "0"], "--samples"),
    (agents.main, ["--runs", "x"], "--runs"),
    (agents.main, ["--threads", "0"], "--threads"),
    (bench_search.main, ["--workers", "0"], "--workers"),
    (lone.main, [], "--out"),
    (remedies.main, ["--samples", "0"], "--samples"),
    (links.main, ["--samples", "-1"], "--samples"),
    (links.main, ["--workers", "0"], "--workers"),
    (links.main, ["--bogus"], "--bogus"),
    (links.main, ["--only", "bogus"], "--only"),
    (steps.main, ["--bench-n", "0"], "--bench-n"),
    (precision.main, ["--bogus"], "--bogus"),
]


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if a command gets past its command line into the work."""

    def reached(*a, **k):
        raise AssertionError("the command started its work on a bad command line")

    from console import app
    from generated import api

    for target in (api, app):
        for name in ("run", "open_console", "ensure_gains", "build"):
            if hasattr(target, name):
                monkeypatch.setattr(target, name, reached)


@pytest.mark.parametrize(("main", "argv", "names"), CASES)
def test_bad_command_line_is_one_line_exit_2(main, argv, names, capsys, no_work, tmp_path):
    os.chdir(tmp_path)  # nothing may be written: the folder stays empty
    try:
        code = run_cli(main, argv)
    finally:
        os.chdir(ROOT)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("error: ") and names in err, err
    assert list(tmp_path.iterdir()) == []


def test_certify_deep_json_is_one_line(tmp_path, capsys):
    deep = tmp_path / "gains.json"
    deep.write_text("[" * 200_000 + "]" * 200_000)
    assert run_cli(synthesis_cli.main, ["certify", str(deep)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nests 200000 levels deep" in err, err


def test_certify_refuses_dev_zero_and_a_fifo_unread(tmp_path):
    """In a child process with 1 GiB of address space and a time limit: reading
    /dev/zero would exhaust the one, opening a FIFO without a writer the other."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    script = textwrap.dedent(
        f"""
        import resource, sys
        from core.errors import run_cli
        from synthesis.cli import main
        resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))
        codes = [run_cli(main, ["certify", f]) for f in ("/dev/zero", {str(fifo)!r})]
        print(codes)
        """
    )
    r = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert r.stdout.strip() == "[2, 2]", r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 2, r.stderr
    assert "/dev/zero: is a character device, not a regular file" in lines[0]
    assert f"{fifo}: is a named pipe (FIFO), not a regular file" in lines[1]
