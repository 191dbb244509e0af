"""``python -m synthesis synth|certify``: files, exit codes, one-line errors, STRICT."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import ROOT

from core.errors import run_cli
from synthesis.cli import main

PY = sys.executable
KEYS = (
    "A0 B0 C0 Gamma Phi Theta Omega T Q lambda_bar1 delta1 delta2 L_bar H Z w "
    "lambda1 lambda2 alpha k1 certificate solver solver_version scenario_sha256"
).split()


def _run(*args: str, tmp: Path, strict: str = "0") -> subprocess.CompletedProcess:
    """A real process: exit status, stderr, environment."""
    env = {**os.environ, "HITL_OUT": str(tmp / "out"), "STRICT": strict}
    return subprocess.run(
        [PY, "-m", "synthesis", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


class _Result:
    def __init__(self, returncode: int, stdout: str, stderr: str) -> None:
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


@pytest.fixture
def cli(capsys, monkeypatch):
    """The same entry point in-process (run_cli around main), to keep the suite fast."""

    def call(*args: str, strict: str = "0") -> _Result:
        monkeypatch.setenv("STRICT", strict)
        capsys.readouterr()
        rc = run_cli(main, list(args))
        out = capsys.readouterr()
        return _Result(rc, out.out, out.err)

    return call


@pytest.fixture(scope="module")
def synth_out(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("synth")
    r = _run("synth", "scenarios/paper.toml", tmp=tmp)
    return tmp, r


def test_synth_paper_writes_every_key(synth_out):
    tmp, r = synth_out
    assert r.returncode == 0, r.stderr
    path = tmp / "out" / "paper" / "gains.json"
    d = json.loads(path.read_text())
    for k in KEYS:
        assert k in d, k
    import hashlib

    assert (
        d["scenario_sha256"]
        == hashlib.sha256((ROOT / "scenarios/paper.toml").read_bytes()).hexdigest()
    )
    assert d["Q"] == [[35.4, 14.9]] and d["lambda1"] == 1.9
    assert all(c["passed"] for c in d["certificate"]["checks"])
    assert d["solver"] in ("CLARABEL", "SCS", "CLARABEL+SCS")
    # no temporary files left behind
    assert [p.name for p in path.parent.iterdir()] == ["gains.json"]


def test_certify_ok_and_hand_edited_theta_fails(synth_out, tmp_path, cli):
    tmp, _ = synth_out
    path = tmp / "out" / "paper" / "gains.json"
    r = cli("certify", str(path))
    assert r.returncode == 0, r.stderr
    d = json.loads(path.read_text())
    d["Theta"][1][0] -= 3.0
    d["Theta"][1][1] -= 3.0
    bad = tmp_path / "gains.json"
    bad.write_text(json.dumps(d))
    r = _run("certify", str(bad), tmp=tmp)  # a real process: exit status 2, one line
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "lmi16" in lines[0] and "hurwitz" in lines[0]
    assert "Traceback" not in r.stderr
    # a given gain edited: a named warning, a failure under STRICT=1
    d2 = json.loads(path.read_text())
    d2["lambda1"] = 0.1  # λ1 w < λ̄1; lambda1 is given in paper.toml -> a warning only
    bad.write_text(json.dumps(d2))
    r = cli("certify", str(bad))
    assert r.returncode == 0 and "warning: given lambda1: lambda1:" in r.stderr
    r = cli("certify", str(bad), strict="1")
    assert r.returncode == 2 and "lambda1" in r.stderr


def test_unstable_zero_scenario_fails_and_writes_nothing(tmp_path, cli):
    text = (ROOT / "scenarios/paper.toml").read_text()
    text = text.replace("C0 = [[1.0, 1.0], [2.0, 2.0]]", "C0 = [[1.0, -1.0], [2.0, -2.0]]")
    text = text.replace('name = "paper"', 'name = "badzero"')
    scen = tmp_path / "badzero.toml"
    scen.write_text(text)
    out = tmp_path / "out" / "badzero" / "gains.json"
    r = cli("synth", str(scen), "--out", str(out))
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "Assumption 2" in r.stderr and "zero(s) 1" in r.stderr
    assert not out.exists()


def test_given_gain_warning_and_strict(tmp_path, cli):
    text = (ROOT / "scenarios/paper.toml").read_text()
    text = text.replace('name = "paper"', 'name = "weak"')
    text = text.replace("lambda1 = 1.9 ", "lambda1 = 0.5 ")  # needs w > 1/0.5 = 2
    scen = tmp_path / "weak.toml"
    scen.write_text(text)
    out = tmp_path / "out" / "weak" / "gains.json"
    r = cli("synth", str(scen), "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "warning: given lambda1: lambda1:" in r.stderr
    d = json.loads(out.read_text())
    assert any(w.startswith("given lambda1") for w in d["certificate"]["warnings"])
    out.unlink()
    for args, strict in (((), "1"), (("--strict",), "0")):  # STRICT=1 or --strict
        r = cli("synth", str(scen), "--out", str(out), *args, strict=strict)
        assert (
            r.returncode == 2 and "strict" in r.stderr and len(r.stderr.strip().splitlines()) == 1
        )
        assert not out.exists()


def test_bad_arguments_one_line(tmp_path, cli):
    r = cli("certify", str(tmp_path / "missing.json"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    r = cli("frobnicate")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
