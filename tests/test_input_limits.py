"""Resource limits checked up front, and one-line errors for every failure a user can cause.

Each case is run through a command-line entry point (``run_cli`` around ``main``, or a
subprocess) and must end in exit status 2 with exactly one line on stderr that names
the field or path, never a traceback, a hang or an out-of-memory kill.
"""

from __future__ import annotations

import builtins
import errno
import io
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import PAPER, ROOT

from core import scenario as S
from core.errors import ScenarioError, UsageError, os_error_line, run_cli
from generated import api
from generated.__main__ import main as sim_main

PAPER_CSV = ROOT / "scenarios" / "paper-csv.toml"


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ") and "Traceback" not in err
    return lines[0]


@pytest.fixture
def no_synthesis(monkeypatch):
    """Any run that gets as far as synthesis fails the test: the refusal must come first."""

    def refuse(*_a, **_k):
        raise AssertionError("the run reached synthesis: the limit was not checked up front")

    monkeypatch.setattr(api, "ensure_gains", refuse)


# --------------------------------------------------------------------------- output size
def test_column_count_is_the_csv_header():
    """The size estimate's column count equals the columns the writer produces."""
    for path in (PAPER, PAPER_CSV):
        sc = S.load_scenario(path)
        assert S.output_columns(sc.N, sc.n, sc.m) == len(api.column_names(sc))
    assert S.output_rows(20.0, 0.01) == 2001  # 0, 0.01, ..., 20


def test_documented_row_count_is_refused_before_any_work(tmp_path, capsys, no_synthesis):
    """1e7 output rows (horizon / output_step, once accepted) exceed the default budget."""
    argv = [
        "sim",
        str(PAPER),
        "--set",
        "integration.output_step=2e-6",
        "--out",
        str(tmp_path),
        "--no-progress",
    ]
    assert run_cli(sim_main, argv) == 2
    line = _one_line_error(capsys)
    assert "integration.output_step" in line and "HITL_OUTPUT_BUDGET" in line
    assert "10000001 output rows x 119 columns" in line
    assert not any(tmp_path.iterdir())  # nothing written


def test_budget_boundary_and_override(monkeypatch):
    """Accepted at exactly the budget, refused one row above; the variable moves the limit."""
    sc = S.load_scenario(PAPER)
    cols = S.output_columns(sc.N, sc.n, sc.m)
    rows = 2001  # the paper's 20 s at 0.01 s
    monkeypatch.setenv(S.OUTPUT_BUDGET_ENV, str(rows * cols * S.OUTPUT_BYTES_PER_VALUE))
    assert api.load(PAPER, {"description": "at the budget"}).integration.output_step == 0.01
    monkeypatch.setenv(S.OUTPUT_BUDGET_ENV, str(rows * cols * S.OUTPUT_BYTES_PER_VALUE - 1))
    with pytest.raises(ScenarioError, match=f"at most {rows - 1} rows"):
        S.load_scenario(PAPER)
    monkeypatch.setenv(S.OUTPUT_BUDGET_ENV, "2e11")  # 1e7 rows x 119 columns x 100 B fit
    assert api.load(PAPER, {"integration.output_step": 2e-6}).integration.output_step == 2e-6
    monkeypatch.setenv(S.OUTPUT_BUDGET_ENV, "lots")
    with pytest.raises(UsageError, match="HITL_OUTPUT_BUDGET='lots'"):
        S.load_scenario(PAPER)


@pytest.mark.slow
def test_bytes_per_value_bounds_the_measured_memory(tmp_path):
    """The estimate's 100 B per CSV value is not below what a real run allocates to make it.

    Independent truth: Python's allocation tracer (numpy and pandas report to it) around a
    real run's integration and output stage (state table, outputs, DataFrame, CSV text),
    at 2e4 output rows, in a fresh process. The kernel's peak RSS was tried first and is
    too noisy for this (other phases set the peak).
    """
    code = (
        "import sys, tracemalloc\n"
        "from generated import api\n"
        "from generated.trajectory_file import trajectory_frame, trajectory_text\n"
        "sc = api.load(sys.argv[1], {'integration.output_step': 1e-3})\n"
        "gains, _ = api.ensure_gains(sc, sys.argv[2])\n"
        "built = api.build(sc, gains, sc.integration.method, api.resolve_codegen(sc.N))\n"
        "s = api.integrator_settings(sc, sc.integration.method)\n"
        "tracemalloc.start()\n"
        "traj = api.simulate(built, sc, s)\n"
        "df = trajectory_frame(built, sc, traj)\n"
        "text = trajectory_text(df, traj)\n"
        "print(tracemalloc.get_traced_memory()[1], df.shape[0] * df.shape[1])\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, str(PAPER), str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    peak, values = (int(v) for v in res.stdout.split()[-2:])
    assert values == 20001 * 119
    per_value = peak / values
    assert per_value <= S.OUTPUT_BYTES_PER_VALUE
    # the rows exist in memory at least once as float64 and once as text
    assert per_value >= 8


# --------------------------------------------------------------------------- traces
def _csv_scenario(tmp_path: Path, trace: str) -> Path:
    text = PAPER_CSV.read_text().replace('"traces/operator.csv"', repr(trace).replace("'", '"'))
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


def _summary(path: Path, *, memory_limit: int | None = None) -> subprocess.CompletedProcess:
    """``python -m symbolic summary PATH`` in a subprocess (a hang or an OOM stays contained)."""

    def limit() -> None:
        if memory_limit:
            resource.setrlimit(resource.RLIMIT_AS, (memory_limit, memory_limit))

    return subprocess.run(
        [sys.executable, "-m", "symbolic", "summary", str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        preexec_fn=limit,
        check=False,
    )


def _assert_refused(res: subprocess.CompletedProcess, *words: str) -> None:
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_trace_that_is_an_endless_device_is_refused(tmp_path):
    res = _summary(_csv_scenario(tmp_path, "/dev/zero"), memory_limit=4 * 2**30)
    _assert_refused(res, "leader.u0_csv", "character device", "regular CSV file")


def test_trace_that_is_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "live.csv"
    os.mkfifo(fifo)
    res = _summary(_csv_scenario(tmp_path, str(fifo)))  # no writer: an open() would block
    _assert_refused(res, "leader.u0_csv", "named pipe (FIFO)")


def test_trace_directory_and_oversize_file_are_refused(tmp_path):
    (tmp_path / "dir.csv").mkdir()
    with pytest.raises(ScenarioError, match=r"leader\.u0_csv: .*dir\.csv is a directory"):
        S.load_scenario(_csv_scenario(tmp_path, "dir.csv"))
    big = tmp_path / "big.csv"
    with big.open("wb") as fh:  # sparse: no disk space used
        fh.truncate(S.MAX_TRACE_BYTES + 1)
    with pytest.raises(ScenarioError, match=r"leader\.u0_csv: .*big\.csv has \d+ bytes, above"):
        S.load_scenario(_csv_scenario(tmp_path, "big.csv"))
    # the limit is on size, not on the file: the shipped trace is still read
    assert S.load_scenario(_csv_scenario(tmp_path, str(PAPER_CSV.parent / "traces/operator.csv")))


def test_scenario_file_that_is_a_device_or_fifo_is_refused(tmp_path):
    _assert_refused(_summary(Path("/dev/zero"), memory_limit=4 * 2**30), "/dev/zero", "(file)")
    fifo = tmp_path / "s.toml"
    os.mkfifo(fifo)
    _assert_refused(_summary(fifo), "named pipe (FIFO)")


# --------------------------------------------------------------------------- --set values
@pytest.mark.parametrize(
    ("value", "words"),
    [
        ("[" * 3000 + "]" * 3000, ("options.ablation", "nested 3000 levels", "at most 16")),
        ("9" * 5000, ("options.ablation", "integer beyond 64 bits", "1e30")),
        ("9" * 25, ("options.ablation", "integer beyond 64 bits")),
    ],
    ids=["deep-array", "5000-digit-int", "25-digit-int"],
)
def test_set_value_limits(value, words, tmp_path, capsys, no_synthesis):
    argv = ["sim", str(PAPER), "--set", f"options.ablation={value}", "--out", str(tmp_path)]
    assert run_cli(sim_main, argv) == 2
    line = _one_line_error(capsys)
    assert line.startswith("error: --set: ") and len(line) < 400
    for w in words:
        assert w in line


def test_set_value_limits_keep_ordinary_values():
    """Brackets inside strings do not count; 16 levels and 19-digit integers are accepted."""
    assert api.parse_override('description="' + "[" * 40 + '"') == ("description", "[" * 40)
    assert api.parse_override("x=" + "[" * 16 + "]" * 16)[1] is not None
    assert api.parse_override("x=9223372036854775807")[1] == 2**63 - 1
    with pytest.raises(ScenarioError, match="nested 17 levels"):
        api.parse_override("x=" + "[" * 17 + "]" * 17)
    with pytest.raises(ScenarioError, match="nested"):  # programmatic overrides too
        value: list = []
        for _ in range(3000):
            value = [value]
        api.load(PAPER, {"options.ablation": value})


# --------------------------------------------------------------------------- long names
def test_long_set_value_gives_a_short_distinct_run_name(tmp_path, capsys):
    """A 300-character value: the run is written under a name < 255 bytes (readable prefix)."""
    a, b = "x" * 300, "x" * 299 + "y"
    na = api.load(PAPER, {"description": a}).name
    nb = api.load(PAPER, {"description": b}).name
    assert na != nb  # same readable prefix, different hash
    assert na.startswith("paper-description-xxxx") and len(na.encode()) <= 255
    argv = [
        "sim",
        str(PAPER),
        "--set",
        f"description={a}",
        "--set",
        "integration.horizon=0.5",
        "--method",
        "cvodes",
        "--opt=-O0",
        "--out",
        str(tmp_path / "out"),
        "--no-progress",
    ]
    os.environ["HITL_BUILD_DIR"] = str(tmp_path / "build")
    try:
        code = run_cli(sim_main, argv)
    finally:
        del os.environ["HITL_BUILD_DIR"]
    assert code == 0, capsys.readouterr().err
    (folder,) = (tmp_path / "out").iterdir()
    assert (folder / "trajectory.csv").is_file() and len(folder.name.encode()) <= 255
    assert folder.name == api.load(PAPER, {"description": a, "integration.horizon": 0.5}).name


def test_explicit_long_variant_is_refused(capsys, no_synthesis):
    argv = ["sim", str(PAPER), "--set", "options.ablation=true", "--variant", "v" * 300]
    assert run_cli(sim_main, argv) == 2
    assert "variant" in _one_line_error(capsys)


# --------------------------------------------------------------------------- file system
def _writes_blocked(folder: Path) -> bool:
    """Whether a chmod 0555 folder refuses writes (not for root)."""
    probe = folder / ".probe"
    try:
        probe.write_text("x")
    except PermissionError:
        return True
    probe.unlink()
    return False


@pytest.fixture
def read_only(monkeypatch):
    """Make a folder read-only: chmod where it works, else EROFS from the kernel calls."""

    def apply(folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        folder.chmod(0o555)
        if _writes_blocked(folder):
            return
        prefix = str(folder.resolve())
        real_open, real_mkdir = os.open, os.mkdir
        writing = os.O_WRONLY | os.O_RDWR | os.O_CREAT

        def inside(path) -> bool:
            return os.path.abspath(os.fspath(path)).startswith(prefix)

        def fake_open(path, flags, *a, **k):
            if flags & writing and inside(path):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fspath(path))
            return real_open(path, flags, *a, **k)

        def fake_mkdir(path, *a, **k):
            if inside(path):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fspath(path))
            return real_mkdir(path, *a, **k)

        monkeypatch.setattr(os, "open", fake_open)
        monkeypatch.setattr(os, "mkdir", fake_mkdir)

    yield apply


@pytest.fixture
def full_disk(monkeypatch):
    """Make a folder's disk full: files opened for writing there write to /dev/full."""

    def apply(folder: Path) -> None:
        prefix = str(folder.resolve())
        real_fdopen, real_open = os.fdopen, io.open

        def fake_fdopen(fd, mode="r", *a, **k):
            if "w" in mode and os.readlink(f"/proc/self/fd/{fd}").startswith(prefix):
                full = os.open("/dev/full", os.O_WRONLY)
                os.dup2(full, fd)  # the same descriptor, now on a full device
                os.close(full)
            return real_fdopen(fd, mode, *a, **k)

        def fake_open(file, mode="r", *a, **k):
            inside = isinstance(file, str | os.PathLike) and os.path.abspath(file).startswith(
                prefix
            )
            if inside and any(c in mode for c in "wax+"):
                return real_open("/dev/full", "wb" if "b" in mode else "w", *a, **k)
            return real_open(file, mode, *a, **k)

        monkeypatch.setattr(os, "fdopen", fake_fdopen)
        monkeypatch.setattr(io, "open", fake_open)
        monkeypatch.setattr(builtins, "open", fake_open)

    yield apply


def test_read_only_output_folder(tmp_path, capsys, read_only):
    out = tmp_path / "out"
    read_only(out)
    argv = ["sim", str(PAPER), "--out", str(out), "--no-progress"]
    try:
        assert run_cli(sim_main, argv) == 2
    finally:
        out.chmod(0o755)
    line = _one_line_error(capsys)
    assert str(out) in line and "writable" in line and "--out DIR" in line
    assert not any(out.iterdir())


def test_full_disk_under_the_output_folder(tmp_path, capsys, full_disk):
    out = tmp_path / "out"
    full_disk(out)
    argv = ["sim", str(PAPER), "--out", str(out), "--no-progress"]
    assert run_cli(sim_main, argv) == 2
    line = _one_line_error(capsys)
    assert f"cannot write {out}/paper/gains.json: No space left on device" in line
    assert "free space on the disk of" in line
    assert [p.name for p in (out / "paper").iterdir()] == []  # no half-written file


def test_full_disk_under_the_build_folder(tmp_path, capsys, full_disk, monkeypatch):
    out, build = tmp_path / "out", tmp_path / "build"
    sc = api.load(PAPER)
    api.ensure_gains(sc, out)  # the run reaches the build without writing to out/
    monkeypatch.setenv("HITL_BUILD_DIR", str(build))
    full_disk(build)
    argv = ["sim", str(PAPER), "--out", str(out), "--no-progress", "--method", "cvodes"]
    assert run_cli(sim_main, argv) == 2
    line = _one_line_error(capsys)
    assert f"cannot write {build}/" in line and "No space left on device" in line
    assert "HITL_BUILD_DIR" in line
    assert not any(p.name.endswith(("source.c", ".so")) for p in build.rglob("*"))


def test_os_error_line_without_a_file_name():
    line = os_error_line(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)))
    assert "\n" not in line and "No space left on device" in line
