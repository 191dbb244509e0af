"""C source of CasADi Functions: renamed copies, the integrator signature, the derivatives.

Facts this module relies on (measured with CasADi 3.8.2): an external Function used
as an integrator's DAE must have exactly the inputs (t, x, z, p, u) and outputs
(ode, alg, quad, zero), and the same library must contain ``jac_<name>`` generated
with ``f.jacobian()`` (direct Newton) or ``fwd1_<name>`` (``f.forward(1)``, GMRES).
Without ``jac_<name>`` the external must carry its Jacobian's sparsity pattern
(``CodeGenerator.add(f, True)``), else CasADi's CVODES/IDAS set-up allocates a dense
nx×nx matrix (N = 500: 2.8 GB, ≈ 400 s; see docs/performance.md).
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca

from core.build_cache import SOURCE_NAME
from core.errors import BuildError
from generated.values import JACOBIAN_STRATEGIES, CodegenSettings


def renamed(f: ca.Function, name: str, *, expand: bool = True, cse: bool = False) -> ca.Function:
    """``f`` under a new name with the same inputs/outputs (SX when possible).

    Parameters
    ----------
    f : casadi.Function
    name : str
    expand : bool
        Expand an MX ``f`` to SX; it stays MX if expansion fails or ``expand`` is False.
    cse : bool
        Eliminate common subexpressions of the SX result (no effect on MX).
    """
    fs = expanded(f) if expand else f
    if fs.is_a("SXFunction"):
        args = fs.sx_in()
        opts = {"cse": True} if cse else {}
        return ca.Function(name, args, fs.call(args), fs.name_in(), fs.name_out(), opts)
    args = f.mx_in()
    return ca.Function(name, args, f.call(args), f.name_in(), f.name_out())


def expanded(f: ca.Function) -> ca.Function:
    """An MX ``f`` as SX (the same operations in the same order: the same numbers, without
    the MX virtual machine's per-node overhead); else ``f`` itself.

    Parameters
    ----------
    f : casadi.Function
    """
    try:
        return f.expand() if f.is_a("MXFunction") else f
    except RuntimeError:  # e.g. calls an external or a Linsol: keep MX
        return f


def check_dyn_signature(f: ca.Function, what: str) -> None:
    """Raise :class:`BuildError` unless ``f`` has the integrator signature ``dyn_in -> dyn_out``.

    Parameters
    ----------
    f : casadi.Function
    what : str
        How ``f`` is named in the error message.
    """
    if list(f.name_in()) != list(ca.dyn_in()) or list(f.name_out()) != list(ca.dyn_out()):
        raise BuildError(
            f"{what}: has inputs ({', '.join(f.name_in())}) and outputs "
            f"({', '.join(f.name_out())}); expected ({', '.join(ca.dyn_in())}) -> "
            f"({', '.join(ca.dyn_out())}) (build it with ca.dyn_in()/ca.dyn_out())"
        )


def generate_source(
    functions: Sequence[ca.Function],
    settings: CodegenSettings,
    with_derivatives: Sequence[str] = (),
) -> tuple[str, tuple[str, ...]]:
    """The C text of ``functions`` with derivatives, and the names of all functions in it.

    Parameters
    ----------
    functions : sequence of casadi.Function
    settings : CodegenSettings
    with_derivatives : sequence of str
        Names that also get ``jac_<name>`` (``f.jacobian()``: sparse, gmres) and/or
        ``fwd1_<name>`` (``f.forward(1)``: gmres, jvp); with jvp their Jacobian's
        sparsity pattern is carried instead (O(nnz) integers, no code).
    """
    if settings.jacobian not in JACOBIAN_STRATEGIES:
        raise BuildError(
            f"CodegenSettings.jacobian: {settings.jacobian!r} must be resolved before "
            "generating code (generated.largescale.choose_plan(N).codegen_settings(...))"
        )
    cg = ca.CodeGenerator(SOURCE_NAME, dict(settings.codegen_options))
    names: list[str] = []
    seen: set[str] = set()
    for f in functions:
        if f.name() in seen:
            raise BuildError(f"generate_source: two functions are named {f.name()!r}")
        seen.add(f.name())
        derive = f.name() in with_derivatives
        # jvp: no jac_<name>, so the pattern must come with the function itself
        cg.add(f, derive and settings.jacobian == "jvp")
        names.append(f.name())
        if derive:
            if settings.jacobian in ("sparse", "gmres"):
                jac = f.jacobian()  # named jac_<name>, as the integrator plugins look it up
                if settings.cse and jac.is_a("SXFunction"):
                    jac = renamed(jac, jac.name(), cse=True)
                cg.add(jac)
                names.append(jac.name())
            if settings.jacobian in ("gmres", "jvp"):
                fwd = f.forward(1)
                cg.add(fwd)
                names.append(fwd.name())
    missing = set(with_derivatives) - seen
    if missing:
        raise BuildError(f"generate_source: with_derivatives names unknown {sorted(missing)}")
    return cg.dump(), tuple(names)
