"""Artifacts carry what they depend on and are re-checked on use.

- gains.json is re-certified on every load (eigenvalue checks, λ1 > λ̄1/w, Lemma 3,
  finiteness, shapes) and must match its scenario; a bad file is refused in one line;
- a reused trajectory needs every input that shaped it unchanged, and trajectory.csv
  must be the file meta.json describes (SHA-256, rows);
- a build-cache entry is loaded only if its library has the hash its manifest records
  for this key; otherwise it is rebuilt;
- leftovers of killed writers are removed (dead PID), live ones kept; a partial run
  says so in its CSV.

The scenario is the two-follower, 0.5 s one of test_sim_api (compiled with -O0 into
a temporary build root).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from helpers import SMALL

from core.artifacts import atomic_write_text, sha256_file
from core.errors import SynthesisError, run_cli
from generated import api, reuse
from generated.__main__ import main as sim_main
from generated.codegen import build_library
from generated.values import CodegenSettings
from verify import pipeline as P

PY = sys.executable


def _dead_pid() -> int:
    """The PID of a process that has exited (and been reaped)."""
    p = subprocess.Popen([PY, "-c", "pass"])
    p.wait()
    return p.pid


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("trust")
    sc = root / "small.toml"
    sc.write_text(SMALL)
    cg = CodegenSettings(optimization="-O0", build_root=str(root / "build"))
    return {"root": root, "scenario": sc, "out": root / "out", "cg": cg}


@pytest.fixture(scope="module")
def gains_file(env):
    sc = api.load(env["scenario"])
    api.ensure_gains(sc, env["out"])
    path = env["out"] / "small" / "gains.json"
    return sc, path, path.read_text()


# --------------------------------------------------------------------------- gains
def _edit(path: Path, text: str | bytes) -> None:
    path.write_bytes(text if isinstance(text, bytes) else text.encode())


def _w(d: dict) -> float:
    """Lemma 3's w from the stored L̄ and Z, by a dense symmetric eigensolver."""
    L, z = np.array(d["L_bar"]), np.diag(np.array(d["Z"]))
    S = L.T * z + z[:, None] * L
    zi = 1.0 / np.sqrt(z)
    return float(np.linalg.eigvalsh(zi[:, None] * S * zi)[0])


BAD_FILES = {
    "lambda1 edited (given 1.9 by the scenario)": (lambda d: d.update(lambda1=0.5), "lambda1"),
    "NaN": (lambda d: d.update(lambda2=float("nan")), "lambda2"),
    "inf in T": (lambda d: d["T"][0].__setitem__(0, float("inf")), "'T'"),
    "ragged": (lambda d: d["Omega"][0].append(1.0), "'Omega'"),
    "wrong shape": (lambda d: d.update(T=[[1.0]]), "shapes"),
    "string scalar": (lambda d: d.update(k1="3"), "'k1'"),
    "missing key": (lambda d: d.pop("Z"), "'Z'"),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_gains_are_refused_in_one_line(env, gains_file, case):
    sc, path, orig = gains_file
    edit, field = BAD_FILES[case]
    d = json.loads(orig)
    edit(d)
    _edit(path, json.dumps(d))
    try:
        with pytest.raises(SynthesisError) as ei:
            api.ensure_gains(sc, env["out"])
    finally:
        _edit(path, orig)
    msg = str(ei.value)
    assert field in msg and "delete" in msg and "make synth" in msg and "\n" not in msg


@pytest.mark.parametrize(
    "content", ['"a string"', "null", "[1, 2]", b"\x7fELF\x00\xff\xfe garbage", '{"A0": ']
)
def test_malformed_gains_are_refused_not_overwritten(env, gains_file, content):
    sc, path, orig = gains_file
    _edit(path, content)
    try:
        with pytest.raises(SynthesisError, match="delete"):
            api.ensure_gains(sc, env["out"])
        assert path.read_bytes() == (content if isinstance(content, bytes) else content.encode())
    finally:
        _edit(path, orig)


def test_eigenvalue_violation_is_refused_under_any_strict(env, gains_file, monkeypatch):
    """Θ edited (Θ is synthesised here) so that ΦA0 − ΘC0 has an eigenvalue in Re > 0."""
    sc, path, orig = gains_file
    d = json.loads(orig)
    d["Theta"][1] = [v - 3.0 for v in d["Theta"][1]]
    Ac = np.array(d["Phi"]) @ np.array(d["A0"]) - np.array(d["Theta"]) @ np.array(d["C0"])
    assert np.linalg.eigvals(Ac).real.max() > 0  # the edit really breaks LMI (16)
    _edit(path, json.dumps(d))
    try:
        for strict in ("0", "1"):
            monkeypatch.setenv("STRICT", strict)
            with pytest.raises(SynthesisError, match="lmi16"):
                api.ensure_gains(sc, env["out"])
    finally:
        _edit(path, orig)


def test_sim_cli_refuses_an_edited_gains_file(env, gains_file, capsys):
    sc, path, orig = gains_file
    d = json.loads(orig)
    d["lambda1"] = 0.5
    _edit(path, json.dumps(d))
    try:
        code = run_cli(sim_main, ["sim", str(env["scenario"]), "--out", str(env["out"])])
    finally:
        _edit(path, orig)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "lambda1" in err[0]


def test_synthesised_lambda1_is_checked_against_lambda_bar1_over_w(env, tmp_path):
    """λ1 synthesised: the file may carry any λ1 with λ1·w > λ̄1, none below (w recomputed here)."""
    ov = {"observer.lambda1": "synthesize"}
    sc = api.load(env["scenario"], ov)
    api.ensure_gains(sc, tmp_path)
    path = tmp_path / sc.name / "gains.json"
    orig = json.loads(path.read_text())
    bound = orig["lambda_bar1"] / _w(orig)
    for factor, ok in ((1.05, True), (0.95, False)):
        d = dict(orig, lambda1=factor * bound)
        _edit(path, json.dumps(d))
        if ok:
            g, _ = api.ensure_gains(sc, tmp_path)
            assert g.lambda1 == factor * bound
        else:
            with pytest.raises(SynthesisError, match="lambda1"):
                api.ensure_gains(sc, tmp_path)


def test_given_gain_warnings_keep_their_meaning(env, tmp_path):
    """A scenario that gives λ1 = 0.5 (λ1·w < λ̄1): a warning at synthesis, so also on reuse."""
    sc = api.load(env["scenario"], {"observer.lambda1": 0.5})
    g1, i1 = api.ensure_gains(sc, tmp_path)
    g2, i2 = api.ensure_gains(sc, tmp_path)
    assert not i1.reused and i2.reused
    assert 0.5 * _w(json.loads(i2.path.read_text())) < sc.observer.lambda_bar1
    assert any(w.startswith("given lambda1") for w in g2.certificate["warnings"])
    assert not g2.certificate["failures"]


# --------------------------------------------------------------------------- trajectory
@pytest.fixture(scope="module")
def base_run(env):
    return api.run(env["scenario"], codegen=env["cg"], out_root=env["out"], progress=False)


def test_meta_records_the_inputs_and_the_csv(env, base_run):
    m = base_run.meta
    data = base_run.csv_path.read_bytes()
    assert m["trajectory_sha256"] == sha256_file(base_run.csv_path)
    assert m["rows"] == len(data.decode().splitlines()) - 1
    assert m["inputs"]["gains_sha256"] == sha256_file(env["out"] / "small" / "gains.json")
    assert m["inputs"]["scenario_sha256"] == api.load(env["scenario"]).sha256
    for path, digest in m["libraries"].items():
        assert sha256_file(path) == digest
    assert api.reuse_problem(env["out"] / "small", api.load(env["scenario"]))[0] is None


def test_unchanged_run_is_reused(env, base_run):
    run = P.obtain_run(env["scenario"], out_root=env["out"], progress=False)
    assert not run.simulated
    assert np.array_equal(run.frame.to_numpy(), base_run.frame.to_numpy())


def test_mismatched_pair_is_not_reused_and_is_resimulated(env, base_run, capsys):
    """A kill between the two renames: the new CSV (here: rows doubled) beside the old meta."""
    folder = env["out"] / "small"
    text = base_run.csv_path.read_text()
    lines = text.splitlines(keepends=True)
    base_run.csv_path.write_text(text + "".join(lines[1:]))
    why, _ = api.reuse_problem(folder, api.load(env["scenario"]))
    assert why is not None and "SHA-256" in why
    os.environ["HITL_BUILD_DIR"] = env["cg"].build_root
    try:
        run = P.obtain_run(env["scenario"], out_root=env["out"], progress=False)
    finally:
        del os.environ["HITL_BUILD_DIR"]
    assert run.simulated and "not reused" in capsys.readouterr().out
    assert sha256_file(folder / "trajectory.csv") == run.meta["trajectory_sha256"]
    assert len(run.frame) == len(lines) - 1


def test_changed_gains_file_or_code_is_not_reused(env, base_run, monkeypatch):
    folder, sc = env["out"] / "small", api.load(env["scenario"])
    gp = folder / "gains.json"
    orig = gp.read_text()
    gp.write_text(json.dumps(json.loads(orig)))  # same numbers, other bytes
    try:
        assert api.reuse_problem(folder, sc)[0] == "gains_sha256 changed since the run"
    finally:
        gp.write_text(orig)
    monkeypatch.setattr(reuse, "code_sha256", lambda: "0" * 64)
    assert api.reuse_problem(folder, sc)[0] == "code_sha256 changed since the run"


TRACE = "t,u0_1\n0.0,{a}\n0.25,0.5\n0.5,{a}\n"


def test_changed_operator_trace_is_not_reused(env, tmp_path):
    """Same TOML, other u0_csv data: the trajectory of the old trace must not be reused."""
    text = SMALL.replace('u0 = ["2*cos(t)"]', 'u0_csv = "trace.csv"').replace(
        'name = "small"', 'name = "traced"'
    )
    (tmp_path / "traced.toml").write_text(text)
    (tmp_path / "trace.csv").write_text(TRACE.format(a=1.0))
    out = tmp_path / "out"
    r = api.run(tmp_path / "traced.toml", codegen=env["cg"], out_root=out, progress=False)
    sc = api.load(tmp_path / "traced.toml")
    assert api.reuse_problem(out / "traced", sc)[0] is None
    (tmp_path / "trace.csv").write_text(TRACE.format(a=-1.0))
    sc2 = api.load(tmp_path / "traced.toml")
    assert sc2.sha256 == sc.sha256  # the TOML did not change ...
    assert api.reuse_problem(out / "traced", sc2)[0] == "u0_trace_sha256 changed since the run"
    r2 = api.run(tmp_path / "traced.toml", codegen=env["cg"], out_root=out, progress=False)
    # ... but the leader's trajectory did (η0 is driven by the trace)
    assert not np.allclose(r.frame["eta0_2"], r2.frame["eta0_2"])


def test_incomplete_run_says_so_in_its_csv(env):
    out = env["root"] / "out-fail"
    with pytest.raises(Exception, match="failed"):
        over = {"integration.max_steps": 3}
        api.run(env["scenario"], overrides=over, variant="fail", codegen=env["cg"], out_root=out)
    folder = out / "small-fail"
    meta = json.loads((folder / "meta.json").read_text())
    first = (folder / "trajectory.csv").read_text().splitlines()[0]
    assert first.startswith("# incomplete: t = ") and meta["complete"] is False
    df, reason = api.read_trajectory(folder / "trajectory.csv")
    assert reason is not None and len(df) == meta["rows"] and list(df.columns)[0] == "t"
    assert df["t"].iloc[-1] == meta["t_reached"]
    sc = api.load(env["scenario"], {"integration.max_steps": 3}, "fail")
    assert api.reuse_problem(folder, sc)[0] == "the run is incomplete"


# --------------------------------------------------------------------------- build cache
def _toy(name: str, expr) -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function(name, [x], [expr(x)])


def _eval_in_subprocess(lib_path: Path, name: str, x: float) -> float:
    """Evaluate in a fresh process: no dlopen of an earlier file at the same path."""
    code = f"import casadi as ca; print(float(ca.external({name!r}, {str(lib_path)!r})({x})))"
    r = subprocess.run([PY, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return float(r.stdout)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "swap"])
def test_bad_cache_entry_is_rebuilt_never_loaded(tmp_path, damage, capsys):
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path))
    a = build_library([_toy("f", ca.sin)], cg)
    b = build_library([_toy("f", ca.cos)], cg)  # same name and signature, other key
    assert a.key != b.key
    so = a.path.read_bytes()
    if damage == "truncate":
        a.path.write_bytes(so[: len(so) // 3])
    elif damage == "garbage":
        a.path.write_bytes(os.urandom(len(so)))
    else:
        a.path.write_bytes(b.path.read_bytes())
    capsys.readouterr()
    c = build_library([_toy("f", ca.sin)], cg)
    err = capsys.readouterr().err.strip().splitlines()
    assert not c.cache_hit and c.key == a.key
    assert len(err) == 1 and "rebuilding" in err[0] and "SHA-256" in err[0]
    assert _eval_in_subprocess(c.path, "f", 0.3) == pytest.approx(np.sin(0.3), rel=1e-15)
    assert build_library([_toy("f", ca.sin)], cg).cache_hit  # the rebuilt entry is trusted


def test_manifest_of_another_key_is_rebuilt(tmp_path, capsys):
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path))
    a = build_library([_toy("f", ca.sin)], cg)
    b = build_library([_toy("f", ca.cos)], cg)
    for name in ("model.so", "manifest.json"):  # the whole entry copied over
        (a.folder / name).write_bytes((b.folder / name).read_bytes())
    c = build_library([_toy("f", ca.sin)], cg)
    assert not c.cache_hit and "not this build" in capsys.readouterr().err
    assert _eval_in_subprocess(c.path, "f", 0.3) == pytest.approx(np.sin(0.3), rel=1e-15)


def test_swapped_library_gives_the_right_trajectory(env, base_run, tmp_path):
    """Another structure's library of the same state size in this key's folder: rebuilt.

    (Numbers such as k2 are runtime parameters and share the library; the operator's
    expression form is structure.)
    """
    other = env["root"] / "sin.toml"
    text = SMALL.replace('u0 = ["2*cos(t)"]', 'u0 = ["2*sin(t)"]').replace('"small"', '"sin"')
    assert text != SMALL
    other.write_text(text)
    rb = api.run(other, codegen=env["cg"], out_root=tmp_path, progress=False)
    assert rb.trajectory.x.shape == base_run.trajectory.x.shape
    assert not np.array_equal(rb.trajectory.x, base_run.trajectory.x)
    Path(base_run.meta["library"]["path"]).write_bytes(
        Path(rb.meta["library"]["path"]).read_bytes()
    )
    out = tmp_path / "again"
    argv = [PY, "-m", "generated", "sim", str(env["scenario"]), "--opt=-O0", "--out", str(out)]
    r = subprocess.run(
        [*argv, "--no-progress"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=Path(__file__).resolve().parent.parent,
        env={**os.environ, "HITL_BUILD_DIR": env["cg"].build_root},
    )
    assert r.returncode == 0, r.stderr
    assert "rebuilding" in r.stderr
    assert (out / "small" / "trajectory.csv").read_bytes() == base_run.csv_path.read_bytes()


# --------------------------------------------------------------------------- leftovers
def test_stale_temp_files_are_removed_live_ones_kept(tmp_path):
    dead, live = _dead_pid(), os.getpid()
    stale = tmp_path / f".trajectory.csv.{dead}.abcd1234.tmp"
    mine = tmp_path / f".trajectory.csv.{live}.abcd1234.tmp"
    old = tmp_path / ".trajectory.csv.k2j4h5g6.tmp"  # a name without a PID, 20 min old
    young = tmp_path / ".trajectory.csv.z9y8x7w6.tmp"
    other = tmp_path / f".meta.json.{dead}.abcd1234.tmp"  # another file's leftover
    for f in (stale, mine, old, young, other):
        f.write_bytes(b"x" * 100)
    t = time.time() - 1200
    os.utime(old, (t, t))
    atomic_write_text(tmp_path / "trajectory.csv", "t\n0.0\n")
    assert not stale.exists() and not old.exists()
    assert mine.exists() and young.exists() and other.exists()
    assert (tmp_path / "trajectory.csv").read_text() == "t\n0.0\n"


def test_stale_build_folders_are_removed_live_ones_kept(tmp_path):
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path))
    dead, live = _dead_pid(), os.getpid()
    stale = tmp_path / f".tmp-0123456789ab-{dead}-xyz"
    mine = tmp_path / f".tmp-0123456789ab-{live}-xyz"
    for d in (stale, mine):
        d.mkdir()
        (d / "model.c").write_text("int x;\n")
    build_library([_toy("g", ca.exp)], cg)
    assert not stale.exists() and mine.exists()
