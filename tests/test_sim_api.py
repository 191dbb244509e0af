"""End-to-end simulation through the API and the CLI (generated/api.py, generated/__main__.py).

A two-follower scenario over 0.5 s keeps the suite fast; the library is compiled
with -O0 (3–4× faster to compile) into a temporary build root.
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import SMALL, TIGHT, TIGHT_BOUND

from core.errors import BuildError, IntegrationError, ScenarioError, run_cli
from generated import api
from generated.__main__ import main as cli_main
from generated.meta import MetaFileError, RunMeta
from generated.progress import progress_bar
from generated.values import CodegenSettings


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    sc = root / "small.toml"
    sc.write_text(SMALL)
    cg = CodegenSettings(optimization="-O0", build_root=str(root / "build"))
    return {"root": root, "scenario": sc, "out": root / "out", "cg": cg}


@pytest.fixture(scope="module")
def base(env):
    r1 = api.run(env["scenario"], codegen=env["cg"], out_root=env["out"], progress=False)
    text1 = r1.csv_path.read_bytes()
    r2 = api.run(env["scenario"], codegen=env["cg"], out_root=env["out"], progress=False)
    return r1, text1, r2


def tight_frame(env, method: str) -> pd.DataFrame:
    """SMALL integrated by ``method`` at :data:`TIGHT` tolerances (libraries from the cache)."""
    sc = api.load(env["scenario"])
    gains, _ = api.ensure_gains(sc, env["out"])
    built = api.build(sc, gains, method, env["cg"])
    s = dataclasses.replace(api.integrator_settings(sc, method, env["cg"]), **TIGHT)
    tr = api.simulate(built, sc, s)
    assert tr.complete, tr.message
    return api.trajectory_frame(built, sc, tr)


@pytest.fixture(scope="module")
def tight_cvodes(base, env):
    return tight_frame(env, "cvodes")


def state_diff(a: pd.DataFrame, b: pd.DataFrame, ref: pd.DataFrame) -> float:
    """Largest difference of the state columns, relative to max |ref| + 1 per column."""
    cols = [c for c in ref.columns if c[:1] in ("p", "q") or c.startswith(("eta", "mu", "ghat"))]
    scale = np.abs(ref[cols].to_numpy()).max(axis=0) + 1.0
    return float((np.abs(a[cols].to_numpy() - b[cols].to_numpy()) / scale).max())


def test_trajectory_columns_rows_and_meta(base, env):
    r1, text1, _ = base
    df = pd.read_csv(r1.csv_path)
    sc = api.load(env["scenario"])
    assert list(df.columns) == api.column_names(sc)
    assert list(df.columns[:3]) == ["t", "eta0_1", "eta0_2"]
    assert "p1_1" in df and "thetahat2_2" in df and "eeta2_2" in df and "V2_2" in df
    assert df.columns[-1] == "V1"
    assert len(df) == 51 and df.t.iloc[-1] == 0.5
    assert np.isfinite(df.to_numpy()).all()
    m = r1.meta  # the file now holds the second run's meta
    assert json.loads(r1.meta_path.read_text())["library"]["key"] == m["library"]["key"]
    assert m["complete"] is True and m["method"] == "cvodes"
    assert m["scenario_sha256"] == sc.sha256
    assert m["gains_sha256"] and Path(m["gains_path"]).is_file()
    assert m["rtol"] == 1e-8 and m["atol"] == 1e-10
    assert m["steps"] > 0 and m["rhs_evals"] >= m["steps"]
    assert 0.3 in m["breakpoints"]
    for k in ("symbolic_build", "codegen", "compile", "integration"):
        assert m["wall_seconds"][k] >= 0
    assert m["cache_hit"] is False and m["library"]["cflags"][-1] == "-O0"
    # the frame returned equals the file written (repr round-trips exactly)
    pd.testing.assert_frame_equal(df, r1.frame, check_exact=True)


def test_trajectory_is_consistent_with_its_own_definitions(base):
    """Columns derived by the closed loop match their definitions on the state columns."""
    df = base[0].frame
    sc_C0 = np.array([[1.0, 1.0], [2.0, 2.0]])
    for i in (1, 2):
        p = df[[f"p{i}_1", f"p{i}_2"]].to_numpy()
        eta = df[[f"eta{i}_1", f"eta{i}_2"]].to_numpy()
        b = df[[f"b{i}_1", f"b{i}_2"]].to_numpy()
        et = df[[f"et{i}_1", f"et{i}_2"]].to_numpy()
        np.testing.assert_allclose(et, p - eta @ sc_C0.T - b, atol=1e-12)  # eq. (28)
        eeta = df[[f"eeta{i}_1", f"eeta{i}_2"]].to_numpy()
        np.testing.assert_allclose(eeta, eta - df[["eta0_1", "eta0_2"]].to_numpy(), atol=1e-12)
    # the leader: η0 = (2(1 - cos t), 2 sin t) for u0 = 2 cos t from rest
    t = df.t.to_numpy()
    np.testing.assert_allclose(df.eta0_1, 2 * (1 - np.cos(t)), atol=1e-6)
    np.testing.assert_allclose(df.eta0_2, 2 * np.sin(t), atol=1e-6)


def test_second_run_reuses_library_and_gives_identical_file(base):
    r1, text1, r2 = base
    assert r2.meta["cache_hit"] is True and r2.meta["wall_seconds"]["compile"] == 0.0
    assert r2.meta["library"]["key"] == r1.meta["library"]["key"]
    assert r2.meta["gains_reused"] is True
    assert r2.csv_path.read_bytes() == text1


@pytest.mark.slow
def test_codegen_is_deterministic_across_processes(base, env):
    """Another interpreter (another hash seed) generates the same C: same cache key."""
    code = (
        "import sys; from generated import api; from generated.values import CodegenSettings;"
        "sc = api.load(sys.argv[1]); g, _ = api.ensure_gains(sc, sys.argv[2]);"
        "b = api.build(sc, g, 'cvodes', CodegenSettings(optimization='-O0', build_root=sys.argv[3]));"
        "print(b.library.key, b.library.cache_hit)"
    )
    envv = dict(os.environ, PYTHONHASHSEED="12345")
    out = subprocess.run(
        [sys.executable, "-c", code, str(env["scenario"]), str(env["out"]), env["cg"].build_root],
        capture_output=True,
        text=True,
        env=envv,
        check=True,
        cwd=Path(__file__).parents[1],
    ).stdout.split()
    assert out == [base[0].meta["library"]["key"], "True"]


def test_ablation_variant_goes_to_its_own_folder(base, env):
    r = api.run(
        env["scenario"],
        overrides={"options.ablation": True},
        codegen=env["cg"],
        out_root=env["out"],
        progress=False,
    )
    assert r.csv_path.parent.name == "small-ablation"
    assert r.meta["overrides"] == {"options.ablation": True}
    assert r.meta["scenario_sha256"] != base[0].meta["scenario_sha256"]
    assert r.meta["library"]["key"] != base[0].meta["library"]["key"]
    df, da = base[0].frame, r.frame
    # eq. (42): u = Ψ without ĝ; the base run's u = ĝ Ψ with ĝ ≠ 1 after the start
    assert np.abs(da.u1_1.to_numpy()[10:] - df.u1_1.to_numpy()[10:]).max() > 1e-3
    assert (env["out"] / "small" / "trajectory.csv").read_bytes() == base[1]  # untouched


def test_idas_and_fixed_agree_with_cvodes(base, env, tight_cvodes):
    """Same closed loop, three integrators: they converge to the same trajectory.

    IDAS and CVODES differ by each one's own error at rtol 1e-8 (the start-up transient);
    the difference must shrink with the tolerance (measured 2026-12-01: 2.1e-5 at the
    fixture's rtol 1e-8/atol 1e-10, 2.5e-7 at rtol 1e-10/atol 1e-13).
    """
    ref = base[0].frame
    cols = [c for c in ref.columns if c[:1] in ("p", "q") or c.startswith(("eta", "mu", "ghat"))]
    scale = np.abs(ref[cols].to_numpy()).max(axis=0) + 1.0

    def err(frame: pd.DataFrame) -> float:
        return float((np.abs(frame[cols].to_numpy() - ref[cols].to_numpy()) / scale).max())

    r = api.run(
        env["scenario"],
        method="idas",
        codegen=env["cg"],
        out_root=env["root"] / "out-idas",
        progress=False,
    )
    assert r.meta["method"] == "idas" and r.meta["form"] == "dae" and r.trajectory.complete
    e_fixture = err(r.frame)
    e_tight = state_diff(tight_frame(env, "idas"), tight_cvodes, ref)
    assert e_tight < TIGHT_BOUND and e_tight < e_fixture / 10, (e_fixture, e_tight)
    # the fixed step (ROS2, h = 1e-3) converges to the same trajectory as its tolerance shrinks
    r = api.run(
        env["scenario"],
        method="fixed",
        codegen=env["cg"],
        out_root=env["root"] / "out-fixed",
        progress=False,
    )
    assert r.meta["method"] == "fixed" and r.meta["library"]["cache_hit"]  # the ODE library
    e3 = err(r.frame)
    sc = api.load(env["scenario"])
    gains, _ = api.ensure_gains(sc, env["out"])
    built = api.build(sc, gains, "fixed", env["cg"])
    s = dataclasses.replace(api.integrator_settings(sc, "fixed"), fixed_rtol=1e-4, fixed_atol=1e-4)
    tr = api.simulate(built, sc, s)
    e4 = err(api.trajectory_frame(built, sc, tr))
    assert tr.complete and tr.stats["refined_intervals"] > 0  # the violent start is bisected
    assert e4 < 3e-3 and e4 < e3 / 4, (e3, e4)


def test_native_agrees_with_cvodes_and_runs_from_the_cli(base, env, capsys, tight_cvodes):
    """The native CVODE driver integrates the same closed loop to the same trajectory.

    At the fixture's rtol 1e-8 the two differ by their own errors of the start-up
    transient; the difference must shrink with the tolerance (measured 2026-12-01: 2.0e-5
    at rtol 1e-8/atol 1e-10, 1.9e-7 at rtol 1e-10/atol 1e-13).
    """
    ref = base[0].frame
    cols = [c for c in ref.columns if c[:1] in ("p", "q") or c.startswith(("eta", "mu", "ghat"))]
    scale = np.abs(ref[cols].to_numpy()).max(axis=0) + 1.0
    out = env["root"] / "out-native"
    argv = [
        "sim",
        str(env["scenario"]),
        "--method",
        "native",
        "--opt=-O0",
        "--out",
        str(out),
        "--no-progress",
    ]
    os.environ["HITL_BUILD_DIR"] = env["cg"].build_root
    try:
        code = run_cli(cli_main, argv)
    finally:
        del os.environ["HITL_BUILD_DIR"]
    assert code == 0, capsys.readouterr().err
    meta = json.loads((out / "small" / "meta.json").read_text())
    assert meta["method"] == "native" and meta["complete"] is True and meta["form"] == "ode"
    assert meta["steps"] > 0 and meta["rhs_evals"] >= meta["steps"]
    df = pd.read_csv(out / "small" / "trajectory.csv")
    assert list(df.columns) == list(ref.columns) and len(df) == len(ref)
    err = float((np.abs(df[cols].to_numpy() - ref[cols].to_numpy()) / scale).max())
    e_tight = state_diff(tight_frame(env, "native"), tight_cvodes, ref)
    assert e_tight < TIGHT_BOUND and e_tight < err / 10, (err, e_tight)
    # deterministic: a second run (library from the cache) writes the same bytes
    first = (out / "small" / "trajectory.csv").read_bytes()
    os.environ["HITL_BUILD_DIR"] = env["cg"].build_root
    try:
        assert run_cli(cli_main, argv) == 0
    finally:
        del os.environ["HITL_BUILD_DIR"]
    assert (out / "small" / "trajectory.csv").read_bytes() == first
    assert json.loads((out / "small" / "meta.json").read_text())["cache_hit"] is True
    # with_method changes only the method (same name), and checks it
    sc = api.load(env["scenario"])
    assert api.with_method(sc, None) is sc
    assert api.with_method(sc, "idas").integration.method == "idas"
    assert api.with_method(sc, "idas").name == sc.name
    with pytest.raises(ScenarioError, match="integration.method"):
        api.with_method(sc, "rk4")
    # a build for another method cannot be run natively
    gains, _ = api.ensure_gains(sc, env["out"])
    built = api.build(sc, gains, "cvodes", env["cg"])
    with pytest.raises(IntegrationError, match="native build"):
        api.simulate(built, sc, api.integrator_settings(sc, "native"))


def test_precision_table_against_the_reference(env):
    """Errors shrink with the tolerance; the reference agrees with CVODES at its tolerance."""
    from benchmarks.precision import precision_table

    sc = api.load(env["scenario"])
    df, unc = precision_table(
        sc, ("cvodes", "native"), (1e-5, 1e-8), 1e-12, codegen=env["cg"], out_root=env["out"]
    )
    # two BDF implementations at rtol 1e-12 (measured 7e-9; at 1e-11 they still differ by
    # 1.5e-6, as in tests/test_agents.py's two-follower case)
    assert unc < 1e-7
    assert list(df.method) == ["cvodes", "cvodes", "native", "native"]
    assert df.complete.all() and (df.steps > 0).all()
    for m in ("cvodes", "native"):
        loose, tight = df[df.method == m].max_err.to_numpy()
        assert tight < loose / 100  # 1000x tighter tolerance: at least 100x closer
    assert (df.atol / df.rtol).round(12).eq(1e-2).all()  # the scenario's atol/rtol ratio
    lay = api.build(sc, api.ensure_gains(sc, env["out"])[0], "cvodes", env["cg"]).closed_loop.layout
    assert lay.name_of(0) == "eta0_1"
    assert lay.name_of(lay.slices[("p", 1)].start + 1) == "p2_2"
    assert lay.name_of(lay.slices[("phi", 1)].start) == "phi2"  # a scalar: its column


def test_failing_integration_writes_incomplete_trajectory_and_exits_2(env, capsys):
    out = env["root"] / "out-fail"
    argv = [
        "sim",
        str(env["scenario"]),
        "--set",
        "integration.max_steps=3",
        "--variant",
        "fail",
        "--opt=-O0",
        "--out",
        str(out),
        "--no-progress",
    ]
    os.environ["HITL_BUILD_DIR"] = env["cg"].build_root
    try:
        code = run_cli(cli_main, argv)
    finally:
        del os.environ["HITL_BUILD_DIR"]
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: cvodes failed after t =")
    folder = out / "small-fail"
    meta = json.loads((folder / "meta.json").read_text())
    assert meta["complete"] is False and meta["message"] in err[0]
    df = pd.read_csv(folder / "trajectory.csv", comment="#")  # line 1: "# incomplete: ..."
    assert len(df) == meta["rows"] < 51 and df.t.iloc[-1] == meta["t_reached"]
    assert np.isfinite(df.to_numpy()).all()
    assert sorted(p.name for p in folder.iterdir()) == ["gains.json", "meta.json", "trajectory.csv"]
    with pytest.raises(IntegrationError):
        api.run(
            env["scenario"],
            overrides={"integration.max_steps": 3},
            variant="fail",
            codegen=env["cg"],
            out_root=out,
            progress=False,
        )


def test_a_native_failure_names_the_largest_state_where_cvode_stood(env):
    """The message ends with CVODE's last step and its largest state, as a CSV column.

    Truth: a second run to t_stop with the steps it needs.
    """
    sc = api.load(env["scenario"])
    built = api.build(sc, api.ensure_gains(sc, env["out"])[0], "native", env["cg"])
    s = dataclasses.replace(api.integrator_settings(sc, "native", env["cg"]), max_steps=1000)
    tr = api.simulate(built, sc, s)
    assert not tr.complete and tr.t_reached < tr.t_stop < sc.integration.output_step
    big = dataclasses.replace(s, max_steps=10**6)
    ref = api.integrate_built(built, built.closed_loop.x0, np.array([0.0, tr.t_stop]), big)
    k = int(np.argmax(np.abs(ref.x[-1])))
    name = built.closed_loop.layout.name_of(k)
    assert name in api.column_names(sc)
    assert abs(ref.x[-1, k]) > 10 * np.abs(built.closed_loop.x0).max()  # not x(0)'s largest
    found = re.search(r"the largest state is (\S+) = (\S+) in magnitude$", tr.message)
    assert found and found[1] == name
    assert float(found[2]) == pytest.approx(abs(ref.x[-1, k]), rel=5e-3)  # 3 digits printed


def test_broken_compile_via_cli_exits_2(env, capsys):
    argv = [
        "sim",
        str(env["scenario"]),
        "--opt=-fno-such-flag-hitl",
        "--out",
        str(env["root"] / "out-broken"),
        "--no-progress",
    ]
    os.environ["HITL_BUILD_DIR"] = env["cg"].build_root
    try:
        code = run_cli(cli_main, argv)
    finally:
        del os.environ["HITL_BUILD_DIR"]
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "compiling" in err[0] and "model.c failed" in err[0] and "no-such-flag" in err[0]
    assert not (env["root"] / "out-broken" / "small" / "trajectory.csv").exists()


def test_overrides_are_validated_like_the_file(env):
    sc = api.load(env["scenario"], {"followers[2].g": 0.5, "integration.method": "fixed"})
    assert sc.followers[1].g.minimum == 0.5 and sc.integration.method == "fixed"
    assert sc.name.startswith("small-followers2.g-0.5-method-fixed")  # the index stays in the name
    with pytest.raises(ScenarioError, match="options.nonsense"):
        api.load(env["scenario"], {"options.nonsense": 1})
    with pytest.raises(ScenarioError, match="sign"):
        api.load(env["scenario"], {"options.sign": "exact"})  # exact needs the fixed method
    with pytest.raises(ScenarioError, match="index"):
        api.load(env["scenario"], {"followers[7].g": 0.5})
    assert api.parse_override("options.ablation=true") == ("options.ablation", True)
    assert api.parse_override("integration.method=fixed") == ("integration.method", "fixed")
    assert api.parse_override("integration.rtol=1e-7") == ("integration.rtol", 1e-7)


def test_method_needs_matching_build(base, env):
    r1 = base[0]
    sc = api.load(env["scenario"])
    gains, _ = api.ensure_gains(sc, env["out"])
    built = api.build(sc, gains, "cvodes", env["cg"])
    assert built.library.cache_hit
    with pytest.raises(IntegrationError, match="DAE"):
        api.simulate(built, sc, api.integrator_settings(sc, "idas"))
    with pytest.raises(BuildError):
        api.build(
            sc,
            gains,
            "cvodes",
            CodegenSettings(compiler="no-such-cc-xyz", build_root=env["cg"].build_root),
        )
    assert r1.trajectory.complete


#: meta.json's keys in the file's order (docs/simulation.md, 'Outputs'); verify reads them
META_KEYS = [
    "scenario",
    "scenario_path",
    "scenario_sha256",
    "overrides",
    "gains_path",
    "gains_sha256",
    "gains_reused",
    "method",
    "form",
    "rtol",
    "atol",
    "max_steps",
    "fixed_step",
    "fixed_rtol",
    "fixed_atol",
    "newton_scheme",
    "linear_solver",
    "integrator_extra_options",
    "horizon",
    "output_step",
    "breakpoints",
    "rows",
    "trajectory_sha256",
    "inputs",
    "libraries",
    "complete",
    "t_reached",
    "message",
    "steps",
    "rhs_evals",
    "stats",
    "library",
    "cache_hit",
    "wall_seconds",
    "sundials_messages",
]


def test_meta_json_keeps_its_keys_and_reads_back_typed(base):
    r1 = base[0]
    text = r1.meta_path.read_text()
    assert list(json.loads(text)) == META_KEYS
    assert list(json.loads(text)["wall_seconds"]) == [
        "load",
        "synthesis",
        "symbolic_build",
        "codegen",
        "compile",
        "integration",
        "outputs",
        "write",
        "total",
    ]
    rec = RunMeta.from_json(text)
    assert rec.to_json() == text and rec.library.key == r1.meta["library"]["key"]
    with pytest.raises(MetaFileError, match="not a run's record"):
        RunMeta.from_json(json.dumps({k: v for k, v in json.loads(text).items() if k != "rows"}))


def test_csv_text_is_repr():
    """The pandas writer gives every float64 the text of Python's repr, which reads back exactly."""
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**64, size=20_000, dtype=np.uint64)  # every sign and exponent
    special = [0.0, -0.0, 1.0, 0.1, 1e16, 1e-5, 1e22, 5e-324, 2.0**-1074, np.inf, -np.inf, np.nan]
    values = np.concatenate([bits.view(np.float64), special]).reshape(-1, 2)
    df = pd.DataFrame(values, columns=["t", "V1"])
    expected = "t,V1\n" + "".join(",".join(map(repr, row)) + "\n" for row in values.tolist())
    assert api.csv_text(df) == expected
    back = pd.read_csv(io.StringIO(api.csv_text(df))).to_numpy()
    assert np.array_equal(back, values, equal_nan=True)
    assert api.csv_text(df.iloc[:0]) == "t,V1\n"


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_is_drawn_only_on_a_terminal_and_when_enabled(monkeypatch):
    monkeypatch.setattr("generated.progress.DELAY_SECONDS", 0.0)
    for stream, enabled in ((io.StringIO(), True), (_Terminal(), False)):
        with progress_bar("sim x", 2.0, enabled, stream) as bar:
            assert bar is None
        assert stream.getvalue() == ""
    term = _Terminal()
    with progress_bar("sim x (cvodes)", 2.0, True, term) as bar:
        bar(1.0)
        bar(5.0)  # beyond the horizon: clipped to 100 %
    out = term.getvalue()
    assert out.startswith("\rsim x (cvodes) [") and out.endswith("\n")
    assert "100.0%" in out and "t = 2.00/2 s" in out
