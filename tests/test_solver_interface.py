"""One integrator interface (generated/solvers/) and one C calling convention (hitl_native.h).

* The ctypes mirror of ``generated/native/hitl_native.h`` has the C layout: a C program
  compiled from the header prints every field's offset and every struct's size, which
  must equal ctypes' (the C compiler is the independent truth).
* The registry: unknown names fail in one line listing the known methods.
* A method registered in a test only (scipy's Radau IIA on the compiled right-hand side)
  runs through the public API on a small scenario at tight tolerances; its result is
  checked against a second integrator (CVODES at the same tolerances).
* Failures carry a :class:`Status` (the solver's flag), not only text.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np
import pytest
from helpers import SMALL, TIGHT, TIGHT_BOUND

from core.errors import IntegrationError, ScenarioError
from generated import api, native, solvers
from generated.built import Built
from generated.schedule import output_grid
from generated.solvers import Solver
from generated.solvers.engine import integrate
from generated.values import CodegenSettings, IntegratorSettings, Status, Trajectory, flag_status


def _c_layout(tmp_path) -> dict[str, int]:
    """``{"Options": size, "Options.rtol": offset, ...}`` as compiled C sees the header."""
    lines = []
    for struct in native.STRUCTS:
        c_name = {"Options": "hitl_options", "Result": "hitl_result"}[struct.__name__]
        lines.append(f'printf("{struct.__name__} %zu\\n", sizeof({c_name}));')
        for field, _ in struct._fields_:
            lines.append(
                f'printf("{struct.__name__}.{field} %zu\\n", offsetof({c_name}, {field}));'
            )
    src = tmp_path / "layout.c"
    src.write_text(
        '#include <stddef.h>\n#include <stdio.h>\n#include "hitl_native.h"\n'
        "int main(void) {\n" + "\n".join(lines) + "\nreturn 0;\n}\n"
    )
    exe = tmp_path / "layout"
    subprocess.run(["gcc", "-I", str(native.NATIVE_DIR), str(src), "-o", str(exe)], check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    return {k: int(v) for k, v in (ln.split() for ln in out.splitlines())}


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_ctypes_mirror_matches_the_header(tmp_path) -> None:
    c = _c_layout(tmp_path)
    for struct in native.STRUCTS:
        assert ctypes.sizeof(struct) == c[struct.__name__], struct.__name__
        for field, _ in struct._fields_:
            py = getattr(struct, field).offset
            assert py == c[f"{struct.__name__}.{field}"], f"{struct.__name__}.{field}"
    assert native.MSG_LEN == ctypes.sizeof(native.Result) - native.Result.msg.offset


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_field_missing_from_the_mirror_is_caught(tmp_path) -> None:
    """The check can fail: a mirror without ``max_steps`` disagrees with the header."""

    class Short(ctypes.Structure):
        _fields_ = [f for f in native.Options._fields_ if f[0] != "max_steps"]

    c = _c_layout(tmp_path)
    assert ctypes.sizeof(Short) != c["Options"] or Short.nt.offset != c["Options.nt"]


def test_unknown_method_is_one_line_listing_the_known(tmp_path) -> None:
    with pytest.raises(IntegrationError) as err:
        solvers.get("rk4")
    text = str(err.value)
    assert "\n" not in text and "'rk4'" in text
    for name in ("cvodes", "native", "idas", "fixed"):
        assert name in text
    sc = api.load(_small(tmp_path))
    with pytest.raises(ScenarioError, match="integration.method"):
        api.with_method(sc, "rk4")


def _small(folder):
    path = folder / "small.toml"
    path.write_text(SMALL)
    return path


def _library_rhs(built: Built) -> Callable[[float, np.ndarray], np.ndarray]:
    """``(t, x) -> ode`` of ``built.dyn`` through the library's C entry point (ctypes).

    The same compiled function ``built.dyn`` calls, with ``built.p`` filled in, without
    CasADi's per-call Python overhead: ~2.5 µs a call instead of ~25 µs (Radau makes
    hundreds of thousands of calls at tight tolerances).
    """
    f = built.dyn_p
    assert f is not None and f.n_in() == 5 and f.n_out() == 4
    lib = ctypes.CDLL(str(built.library.path))
    fn, work = getattr(lib, f.name()), getattr(lib, f.name() + "_work")
    dp, cint = ctypes.POINTER(ctypes.c_double), ctypes.c_longlong
    sizes = [cint() for _ in range(4)]
    assert work(*(ctypes.byref(s) for s in sizes)) == 0
    n_arg, n_res, n_iw, n_w = (max(s.value, 1) for s in sizes)
    fn.argtypes = [ctypes.POINTER(dp), ctypes.POINTER(dp), ctypes.c_void_p, ctypes.c_void_p]
    fn.argtypes += [ctypes.c_int]
    tb, xb = np.zeros(1), np.zeros(f.nnz_in(1))
    pb, out = np.ascontiguousarray(built.p, dtype=float), np.zeros(f.nnz_out(0))
    assert pb.size == f.nnz_in(3) and f.nnz_in(2) == f.nnz_in(4) == 0
    arg, res = (dp * n_arg)(), (dp * n_res)()
    arg[0], arg[1], arg[3] = (b.ctypes.data_as(dp) for b in (tb, xb, pb))
    res[0] = out.ctypes.data_as(dp)
    iw, w = np.zeros(n_iw, dtype=np.int64), np.zeros(n_w)

    def rhs(t: float, x: np.ndarray, _alive=(pb, lib)) -> np.ndarray:  # buffers arg points to
        tb[0], xb[:] = t, x
        assert fn(arg, res, iw.ctypes.data, w.ctypes.data, 0) == 0
        return out.copy()

    return rhs


class ScipyRadau(Solver):
    """scipy's Radau IIA on ``Built.dyn``, restarted at breakpoints: a toy method for the test."""

    name = "toy-scipy-radau"
    form = "ode"
    summary = "scipy Radau IIA (test only)"

    def run(
        self,
        built: Built,
        x0: np.ndarray,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float] = (),
        progress: Callable[[float], None] | None = None,
    ) -> Trajectory:
        from scipy.integrate import solve_ivp

        e = ca.DM(0, 1)
        tt, xx, em = ca.MX.sym("t"), ca.MX.sym("x", built.dyn.size1_in(1)), ca.MX(0, 1)
        jac = ca.Function("J", [tt, xx], [ca.jacobian(built.dyn(tt, xx, em, em, em)[0], xx)])
        rhs = _library_rhs(built)
        t0 = float(t_out[0])
        expected = np.asarray(built.dyn(t0, x0, e, e, e)[0], dtype=float).ravel()
        assert np.array_equal(rhs(t0, np.asarray(x0, dtype=float)), expected)

        def J(t, x):
            return np.asarray(jac(t, x), dtype=float)

        t_out = np.asarray(t_out, dtype=float)
        cuts = [t_out[0], *(b for b in sorted(breakpoints) if t_out[0] < b < t_out[-1]), t_out[-1]]
        X, x, steps = [np.asarray(x0, dtype=float)], np.asarray(x0, dtype=float), 0
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            ts = t_out[(t_out > a) & (t_out <= b)]
            sol = solve_ivp(
                rhs, (a, b), x, "Radau", ts, rtol=settings.rtol, atol=settings.atol, jac=J
            )
            assert sol.success, sol.message
            X.extend(sol.y.T)
            x = sol.y[:, -1] if len(ts) and ts[-1] == b else sol.sol(b) if sol.sol else x
            steps += sol.nfev
        return Trajectory(
            t=t_out,
            x=np.array(X),
            z=None,
            method=self.name,
            status=Status.OK,
            t_reached=float(t_out[-1]),
            message="",
            stats={"steps": steps, "rhs_evals": steps, "wall_seconds": 0.0},
        )


@pytest.fixture()
def toy_method():
    solver = solvers.register(ScipyRadau())
    yield solver
    solvers.unregister(solver.name)


def test_a_method_registered_in_a_test_runs_through_the_api(tmp_path, toy_method) -> None:
    """Registered here only, the method runs through api.run; CVODES is the second
    implementation it must agree with (both at tight tolerances, test_sim_api's bound)."""
    path = _small(tmp_path)
    # one run at tight tolerances through api.run (the file's own are looser), compared below
    tight = {f"integration.{k}": TIGHT[k] for k in ("rtol", "atol", "max_steps")}
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path / "build"))
    out = tmp_path / "out"
    res = api.run(
        path,
        overrides=tight,
        variant="tight",
        method=toy_method.name,
        codegen=cg,
        out_root=out,
        progress=False,
    )
    assert res.trajectory.complete and res.trajectory.method == toy_method.name
    assert res.meta["method"] == toy_method.name
    assert (out / "small-tight" / "trajectory.csv").is_file()
    sc = api.load(path, tight, "tight")
    gains, _ = api.ensure_gains(sc, out)
    s = api.integrator_settings(sc, "cvodes", cg)
    assert (s.rtol, s.atol, s.max_steps) == (TIGHT["rtol"], TIGHT["atol"], TIGHT["max_steps"])
    ref = api.simulate(api.build(sc, gains, "cvodes", cg), sc, s)
    assert ref.complete
    a, b = res.trajectory.x, ref.x
    scale = np.max(np.abs(b), axis=0) + 1.0
    assert np.max(np.abs(a - b) / scale) < TIGHT_BOUND


def test_a_registered_method_may_be_named_in_a_scenario_file(tmp_path) -> None:
    """register declares the name to the loader (with its fixed_step flag); unregister
    withdraws it, and the file is refused again in one line."""
    path = _small(tmp_path)
    text = path.read_text()
    assert 'method = "cvodes"' in text
    path.write_text(text.replace('method = "cvodes"', 'method = "toy-scipy-radau"'))
    solver = solvers.register(ScipyRadau())
    try:
        assert api.load(path).integration.method == solver.name
        exact = tmp_path / "exact.toml"
        exact.write_text(path.read_text().replace('sign = "tanh"', 'sign = "exact"'))
        with pytest.raises(ScenarioError, match="options.sign"):
            api.load(exact)  # a variable-step method may not integrate the exact sign
    finally:
        solvers.unregister(solver.name)
    with pytest.raises(ScenarioError, match="integration.method"):
        api.load(path)


def test_failures_carry_a_status() -> None:
    """x' = x² from x(0) = 1 blows up at t = 1: CVODES and ROS2 stop with a status."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x")
    e = ca.SX(0, 1)
    f = ca.Function(
        "blow",
        [t, x, e, e, e],
        [x**2, e, e, e],
        ["t", "x", "z", "p", "u"],
        ["ode", "alg", "quad", "zero"],
    )
    tg = output_grid(2.0, 0.25)
    tr = integrate(f, np.ones(1), tg, IntegratorSettings(max_steps=500))
    assert not tr.complete and tr.status is not Status.OK and tr.t_reached < 1.0
    short = integrate(f, np.ones(1), tg, IntegratorSettings(max_steps=3))
    assert short.status is Status.STEP_LIMIT
    ok = integrate(f, np.ones(1), output_grid(0.5, 0.25), IntegratorSettings())
    assert ok.status is Status.OK and ok.complete
    # the exact solution 1/(1 - t) at t = 0.5
    assert abs(ok.x[-1, 0] - 2.0) < 1e-4


def test_flag_names_map_to_statuses() -> None:
    assert flag_status("CV_TOO_MUCH_WORK") is Status.STEP_LIMIT
    assert flag_status("IDA_CONV_FAIL") is Status.CONV_FAIL
    assert flag_status("CV_ERR_FAILURE") is Status.ERROR_TEST
    assert flag_status("CV_TOO_CLOSE") is Status.TOO_CLOSE
    assert flag_status("CV_SOMETHING_NEW") is Status.FAILED
