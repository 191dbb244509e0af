"""Code generation, compilation and the build cache (generated/codegen.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from platformdirs import user_cache_dir

from core import build_cache
from core.errors import BuildError
from generated import codegen
from generated.__main__ import main as gen_main
from generated.codegen import build_library
from generated.compiler import compile_source
from generated.csource import check_dyn_signature, renamed
from generated.largescale import choose_plan
from generated.values import CodegenSettings


def dyn(name: str, c: float = 0.3) -> ca.Function:
    """A nonlinear ODE in integrator form (tanh, sqrt, division, time dependence)."""
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", 3)
    e = ca.SX(0, 1)
    rhs = ca.vertcat(
        x[1],
        -2 * x[0] - c * x[1] + ca.tanh(x[2] / 0.05) + ca.sin(3 * t),
        -x[2] / (1 + x[0] ** 2) + ca.sqrt(1 + x[1] ** 2) * ca.cos(t),
    )
    return ca.Function(name, [t, x, e, e, e], [rhs, e, e, e], ca.dyn_in(), ca.dyn_out())


@pytest.fixture
def settings(tmp_path):
    return CodegenSettings(build_root=str(tmp_path / "build"))


def test_library_equals_symbolic_function_at_random_inputs(settings):
    f = dyn("toy")
    outs = ca.Function(
        "toy_out",
        [f.sx_in(0), f.sx_in(1)],
        [ca.mtimes(f.sx_in(1), f.sx_in(1).T), ca.sumsqr(f.sx_in(1))],
        ["t", "x"],
        ["xx", "n2"],
    )
    lib = build_library([f, outs], settings, with_derivatives=["toy"])
    assert set(lib.names) == {"toy", "jac_toy", "toy_out"}
    ext, jext, oext = lib.function("toy"), lib.function("jac_toy"), lib.function("toy_out")
    jac = f.jacobian()
    rng = np.random.default_rng(5)
    for _ in range(50):
        t = rng.uniform(-5, 5)
        x = rng.normal(scale=3, size=3)
        np.testing.assert_allclose(
            np.array(ext(t, x, [], [], [])[0]),
            np.array(f(t, x, [], [], [])[0]),
            rtol=1e-12,
            atol=1e-12,
        )
        a = jac(t, x, [], [], [], 0, 0, 0, 0)
        b = jext(t, x, [], [], [], 0, 0, 0, 0)
        assert len(a) == len(b)
        for u, v in zip(a, b, strict=True):
            assert u.sparsity() == v.sparsity()
            np.testing.assert_allclose(np.array(v), np.array(u), rtol=1e-12, atol=1e-12)
        for u, v in zip(outs(t, x), oext(t, x), strict=True):
            np.testing.assert_allclose(np.array(v), np.array(u), rtol=1e-12, atol=1e-12)


def test_jacobian_is_sparse_not_dense(settings):
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", 40)
    e = ca.SX(0, 1)
    f = ca.Function(
        "chain",
        [t, x, e, e, e],
        [-x + ca.vertcat(0, x[:-1] ** 2), e, e, e],
        ca.dyn_in(),
        ca.dyn_out(),
    )
    lib = build_library([f], settings, with_derivatives=["chain"])
    jx = lib.function("jac_chain").sparsity_out(1)  # jac_ode_x
    assert jx.size() == (40, 40)
    assert jx.nnz() == 40 + 39  # diagonal + subdiagonal, not 1600


def test_gmres_strategy_adds_forward_derivative(settings):
    from dataclasses import replace

    lib = build_library([dyn("toy")], replace(settings, jacobian="gmres"), ["toy"])
    assert "fwd1_toy" in lib.names and "jac_toy" in lib.names


def test_cache_reused_when_unchanged_rebuilt_when_model_or_option_changes(settings, tmp_path):
    from dataclasses import replace

    a = build_library([dyn("toy")], settings, ["toy"])
    assert not a.cache_hit and a.path.is_file() and a.compile_seconds > 0
    b = build_library([dyn("toy")], settings, ["toy"])
    assert b.cache_hit and b.key == a.key and b.compile_seconds == 0.0
    # a different build root holds the same key (the root is not part of the key)
    other = build_library([dyn("toy")], replace(settings, build_root=str(tmp_path / "b2")), ["toy"])
    assert other.key == a.key and not other.cache_hit
    # a changed model
    c = build_library([dyn("toy", c=0.31)], settings, ["toy"])
    assert not c.cache_hit and c.key != a.key
    # a changed option: optimisation, extra flags, Jacobian strategy
    for s2 in (
        replace(settings, optimization="-O0"),
        replace(settings, extra_cflags=("-DHITL_TEST=1",)),
        replace(settings, jacobian="gmres"),
    ):
        d = build_library([dyn("toy")], s2, ["toy"])
        assert not d.cache_hit and d.key not in (a.key, c.key)
        assert build_library([dyn("toy")], s2, ["toy"]).cache_hit
    # the original is still served from the cache
    assert build_library([dyn("toy")], settings, ["toy"]).cache_hit


def test_incomplete_cache_entry_is_rebuilt(settings):
    a = build_library([dyn("toy")], settings, ["toy"])
    (a.folder / "manifest.json").unlink()
    b = build_library([dyn("toy")], settings, ["toy"])
    assert not b.cache_hit and b.key == a.key and (b.folder / "manifest.json").is_file()


def test_broken_compile_reports_first_errors_and_source(settings, tmp_path):
    broken = tmp_path / "broken.h"
    broken.write_text("#error deliberately broken for the test\n")
    from dataclasses import replace

    s2 = replace(settings, extra_cflags=("-include", str(broken)))
    with pytest.raises(BuildError) as ei:
        build_library([dyn("toy")], s2, ["toy"])
    msg = str(ei.value)
    assert "\n" not in msg
    assert "deliberately broken" in msg
    src = msg.split("compiling ")[1].split(" failed")[0]
    assert src.endswith("model.c")
    from pathlib import Path

    assert Path(src).is_file()  # the source is kept where the message says
    root = Path(codegen.cache_root(settings))
    entries = [p for p in root.iterdir() if p.name not in ("failed",)]
    assert entries == []  # no cache entry, no temporary folder left behind


def test_compile_source_syntax_error(tmp_path, settings):
    with pytest.raises(BuildError, match="error"):
        compile_source("int f( { return 0; }\n", settings, tmp_path / "x")
    assert not (tmp_path / "x" / "model.so").exists()


def test_missing_compiler(settings):
    from dataclasses import replace

    with pytest.raises(BuildError, match="not found"):
        build_library([dyn("toy")], replace(settings, compiler="no-such-cc-xyz"), ["toy"])


def test_bad_settings_and_signature():
    with pytest.raises(BuildError, match="jacobian"):
        CodegenSettings(jacobian="dense-please")
    with pytest.raises(BuildError, match="linear_solver"):
        CodegenSettings(linear_solver="nope")
    x = ca.SX.sym("x")
    with pytest.raises(BuildError, match="expected"):
        check_dyn_signature(ca.Function("f", [x], [x]), "f")
    check_dyn_signature(dyn("ok"), "ok")


def test_renamed_keeps_values_and_names():
    f = dyn("toy")
    g = renamed(f, "other")
    assert g.name() == "other" and g.name_in() == f.name_in() and g.name_out() == f.name_out()
    args = f.mx_in()
    mx = ca.Function("mxf", args, f.call(args), f.name_in(), f.name_out())
    h = renamed(mx, "h")
    assert h.is_a("SXFunction")
    xs = np.array([0.3, -1.0, 2.0])
    np.testing.assert_allclose(
        np.array(h(0.7, xs, [], [], [])[0]), np.array(f(0.7, xs, [], [], [])[0]), rtol=1e-15
    )


def test_jvp_strategy_has_forward_derivative_only(settings):
    from dataclasses import replace

    s2 = replace(settings, jacobian="jvp")
    lib = build_library([dyn("toy")], s2, ["toy"])
    assert "fwd1_toy" in lib.names and "jac_toy" not in lib.names
    # no Jacobian to precondition with: GMRES must run unpreconditioned
    assert choose_plan(1, "jvp", linear_solver=s2.linear_solver).integrator_options == {
        "newton_scheme": "gmres",
        "use_preconditioner": False,
        "max_krylov": 20,
    }
    f = dyn("toy")
    fwd_sym, fwd_ext = f.forward(1), lib.function("fwd1_toy")
    rng = np.random.default_rng(1)
    args = [
        0.4,
        rng.normal(size=3),
        [],
        [],
        [],
        *[np.zeros(k.shape) for k in f.call([0.4, np.zeros(3), [], [], []])],
    ]
    seeds = [1.0, rng.normal(size=3), [], [], []]
    a = fwd_sym(*args, *seeds)
    b = fwd_ext(*args, *seeds)
    for u, v in zip(a, b, strict=True):
        np.testing.assert_allclose(np.array(v), np.array(u), rtol=1e-12, atol=1e-12)


def test_concurrent_identical_builds_share_one_entry(settings):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as ex:
        libs = list(ex.map(lambda _: build_library([dyn("conc")], settings, ["conc"]), range(2)))
    assert libs[0].key == libs[1].key and libs[0].path.is_file()
    entries = [p for p in codegen.cache_root(settings).iterdir() if not p.name.startswith(".")]
    assert [p.name for p in entries] == [libs[0].key]
    x = np.array([0.1, 0.2, 0.3])
    for lib in libs:
        np.testing.assert_allclose(
            np.array(lib.function("conc")(0.5, x, [], [], [])[0]),
            np.array(dyn("conc")(0.5, x, [], [], [])[0]),
            rtol=1e-12,
        )


def test_cse_shrinks_the_code_and_keeps_the_values(tmp_path):
    """CodegenSettings.cse: fewer instructions (right-hand side and Jacobian), same numbers."""
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", 3)
    e = ca.SX(0, 1)
    s = ca.sin(x[0] * x[1]) + ca.exp(t * x[2])  # built twice below: identical subtrees
    s2 = ca.sin(x[0] * x[1]) + ca.exp(t * x[2])
    rhs = ca.vertcat(s * x[0], s2 * x[1], ca.tanh(s) + s2**2)
    f = ca.Function("dup", [t, x, e, e, e], [rhs, e, e, e], ca.dyn_in(), ca.dyn_out())
    plain, shared = renamed(f, "dup"), renamed(f, "dup", cse=True)
    assert shared.n_instructions() < plain.n_instructions()
    libs = {
        flag: build_library(
            [renamed(f, "dup", cse=flag)],
            CodegenSettings(build_root=str(tmp_path / str(flag)), cse=flag),
            with_derivatives=["dup"],
        )
        for flag in (False, True)
    }
    assert libs[False].key != libs[True].key  # the setting is part of the cache key
    rng = np.random.default_rng(3)
    for _ in range(20):
        tt, xx = rng.uniform(-1, 1), rng.normal(size=3)
        a = [libs[k].function("dup")(tt, xx, [], [], [])[0] for k in (False, True)]
        np.testing.assert_allclose(np.array(a[1]), np.array(a[0]), rtol=1e-14, atol=1e-14)
        j = [libs[k].function("jac_dup")(tt, xx, [], [], [], 0, 0, 0, 0) for k in (False, True)]
        for u, v in zip(j[0], j[1], strict=True):
            np.testing.assert_allclose(np.array(v), np.array(u), rtol=1e-14, atol=1e-14)


def test_default_cache_is_outside_the_package_and_env_overrides_it(tmp_path, monkeypatch):
    """The default root is the user cache (XDG_CACHE_HOME honoured), never under the package."""
    package = Path(codegen.__file__).resolve().parent
    monkeypatch.delenv("HITL_BUILD_DIR", raising=False)
    root = codegen.cache_root(CodegenSettings())
    assert package not in root.resolve().parents and root.resolve() != package
    assert root == Path(user_cache_dir("hitl-formation")) / "build"
    env = subprocess.run(
        [
            sys.executable,
            "-c",
            "from core.build_cache import DEFAULT_BUILD_ROOT as r; print(r)",
        ],
        env={**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")},
        capture_output=True,
        text=True,
        check=True,
    )
    assert env.stdout.strip() == str(tmp_path / "xdg" / "hitl-formation" / "build")
    monkeypatch.setenv("HITL_BUILD_DIR", str(tmp_path / "mine"))
    assert codegen.cache_root(CodegenSettings()) == tmp_path / "mine"
    assert codegen.cache_root(CodegenSettings(build_root=str(tmp_path / "set"))) == tmp_path / "set"


def test_clear_cache_removes_only_what_the_cache_made(settings, tmp_path, capsys, monkeypatch):
    root = codegen.cache_root(settings)
    lib = build_library([dyn("toy")], settings, ["toy"])
    (root / "failed" / ("0" * 64)).mkdir(parents=True)
    (root / ".tmp-abc-1-x").mkdir()
    for kind in ("gains", "models"):  # the start-up caches (core/models/cache.py)
        (root / kind).mkdir()
        (root / kind / f"{'1' * 64}.json").write_text("{}")
    (root / "notes").mkdir()  # not the cache's: kept
    (root / "notes" / "keep.txt").write_text("mine")
    removed = build_cache.clear_cache(root)
    made = [".tmp-abc-1-x", "failed", "gains", "models", lib.key]
    assert sorted(p.name for p in removed) == sorted(made)
    assert [p.name for p in root.iterdir()] == ["notes"]
    (root / "notes" / "keep.txt").unlink()
    (root / "notes").rmdir()
    build_library([dyn("toy")], settings, ["toy"])
    monkeypatch.setenv("HITL_BUILD_DIR", str(root))
    assert gen_main(["cache", "--clear"]) == 0
    assert capsys.readouterr().out.strip() == str(root) and not root.exists()
