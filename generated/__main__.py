"""``python -m generated sim SCENARIO`` (``make sim``): synthesize if needed, build, integrate, write.

Writes ``out/<name>/trajectory.csv`` and ``meta.json``; exit status 2 with one line on
stderr on any toolkit error (an incomplete trajectory is still written first).
``python -m generated cache [--clear]`` prints (and empties) the build cache folder.
"""

from __future__ import annotations

import argparse
import sys

from core import methods
from core.cli_args import positive, word
from core.errors import CliParser, run_cli
from core.overrides import add_scenario_knobs, scenario_knobs


def _parser() -> argparse.ArgumentParser:
    ap = CliParser(prog="python -m generated", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sim = sub.add_parser("sim", help="simulate a scenario with generated C")
    sim.add_argument("scenario", help="scenario TOML file")
    sim.add_argument("--method", choices=methods.METHODS, help="override integration.method")
    add_scenario_knobs(sim)
    sim.add_argument("--ablation", action="store_true", help="same as --set options.ablation=true")
    sim.add_argument(
        "--opt", type=word, default="-O1", help="compiler optimisation flag (default -O1)"
    )
    sim.add_argument("--compiler", type=word, default="gcc")
    sim.add_argument(
        "--jacobian",
        choices=("auto", "sparse", "gmres", "jvp"),
        default="auto",
        help="Newton linear algebra: auto (default) = sparse (direct) for N <= 20, else jvp "
        "(matrix-free GMRES, generated/largescale.py)",
    )
    sim.add_argument(
        "--fixed-tol",
        type=positive,
        default=None,
        help="error-test tolerance of the fixed-step method's bisection safeguard (default 1e-3)",
    )
    sim.add_argument("--linear-solver", type=word, default="csparse")
    sim.add_argument("--out", default=None, help="output root (default out/ or $HITL_OUT)")
    sim.add_argument("--no-progress", action="store_true")
    cache = sub.add_parser(
        "cache", help="print the build cache folder ($HITL_BUILD_DIR or the user cache)"
    )
    cache.add_argument(
        "--clear", action="store_true", help="remove its compiled libraries and temporary folders"
    )
    return ap


def main(argv: list[str]) -> int:
    """Run ``sim`` or ``cache``; 0 on success (``run_cli`` turns toolkit errors into status 2).

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.
    """
    args = _parser().parse_args(argv)
    return _cache(args.clear) if args.cmd == "cache" else _sim(args)


def _cache(clear: bool) -> int:
    """Print the build cache root; with ``clear``, empty it first and say how many entries went."""
    from core.build_cache import clear_cache, default_build_root

    root = default_build_root()
    if clear:
        removed = clear_cache(root)
        print(f"{root}: removed {len(removed)} cache folders", file=sys.stderr)
    print(root)
    return 0


def _sim(args: argparse.Namespace) -> int:
    """``sim``: run :func:`generated.api.run` and print a one-line summary on stderr."""
    from generated import api
    from generated.values import CodegenSettings

    overrides, variant = scenario_knobs(args, {"options.ablation": True} if args.ablation else None)
    cg = CodegenSettings(
        compiler=args.compiler,
        optimization=args.opt,
        jacobian=args.jacobian,
        linear_solver=args.linear_solver,
    )
    res = api.run(
        args.scenario,
        overrides=overrides,
        variant=variant,
        method=args.method,
        codegen=cg,
        out_root=args.out,
        progress=not args.no_progress,
        fixed_tol=args.fixed_tol,
    )
    m = res.record
    w = m.wall_seconds
    print(
        f"{res.csv_path}: {m.rows} rows, method {m.method}, {m.steps} steps, "
        f"{m.rhs_evals} RHS evaluations; library {'reused' if m.cache_hit else 'compiled'}; "
        f"build {w.symbolic_build:.2f} s + codegen {w.codegen:.2f} s + compile "
        f"{w.compile:.2f} s, integration {w.integration:.2f} s",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
