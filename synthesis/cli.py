"""Command line: ``synth SCENARIO [--set KEY=VALUE] [--variant NAME] [--strict] [--out FILE]`` and ``certify GAINS [--strict]``.

Exit codes: 0 ok (warnings about given gains go to stderr), 2 on failure with one
line on stderr (via :func:`core.errors.run_cli`). ``STRICT=1`` in the
environment has the effect of ``--strict``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from core.artifacts import out_dir
from core.errors import CliParser, SynthesisError, strict_mode
from core.overrides import add_scenario_knobs, load, scenario_knobs
from synthesis.api import synthesize
from synthesis.certificate import certify
from synthesis.gains import load_gains, save_gains


def _strict(flag: bool) -> bool:
    """``--strict`` or ``STRICT=1`` (one reading for every command: :func:`strict_mode`)."""
    return strict_mode(flag)


def main(argv: list[str]) -> int:
    """Entry point; returns the exit status (errors are raised as ToolkitError).

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.
    """
    ap = CliParser(prog="python -m synthesis", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("synth", help="synthesise and certify gains for a scenario")
    s.add_argument("scenario")
    add_scenario_knobs(s)
    s.add_argument("--strict", action="store_true", help="warnings about given gains fail")
    s.add_argument("--out", default=None, help="output file (default out/<name>/gains.json)")
    c = sub.add_parser("certify", help="re-check a gains.json from its numbers alone")
    c.add_argument("gains")
    c.add_argument("--strict", action="store_true", help="warnings about given gains fail")
    args = ap.parse_args(argv)
    strict = _strict(args.strict)

    if args.cmd == "synth":
        scen = load(args.scenario, *scenario_knobs(args))
        g = synthesize(scen, strict=strict)
        path = Path(args.out) if args.out else out_dir(scen.name) / "gains.json"
        save_gains(g, path)
        cert = g.certificate
        for wline in cert["warnings"]:
            print(f"warning: {wline}", file=sys.stderr)
        nchk = len(cert["checks"])
        npass = sum(ch["passed"] for ch in cert["checks"])
        print(
            f"{path}: w = {g.w:.6g} ({g.info['lemma3']['used']} Z), lambda1 = {g.lambda1:.6g}, "
            f"lambda2 = {g.lambda2:.6g}, Q = {g.Q.ravel().round(6).tolist()}, k1 = {g.k1:.6g}; "
            f"certificate {npass}/{nchk} checks pass, {len(cert['warnings'])} warning(s); "
            f"solver {g.info['solver']}"
        )
        return 0

    g = load_gains(args.gains)
    try:
        cert = certify(g)
    except (ValueError, IndexError, TypeError, ArithmeticError) as exc:
        raise SynthesisError(
            f"{args.gains}: certify cannot evaluate the numbers ({type(exc).__name__}: {exc})"
        ) from None
    failures, warnings = cert.failures(), cert.warnings()
    if failures:
        raise SynthesisError(f"{args.gains}: certificate fails: " + "; ".join(failures))
    if strict and warnings:
        raise SynthesisError(f"{args.gains}: certificate (strict) fails: " + "; ".join(warnings))
    for wline in warnings:
        print(f"warning: {wline}", file=sys.stderr)
    npass = sum(ch.passed for ch in cert.checks)
    print(
        f"{args.gains}: {npass}/{len(cert.checks)} checks pass"
        + (f", {len(warnings)} warning(s) about given gains" if warnings else "")
        + (f"; {cert.proof_summary()}" if cert.proof_summary() else "")
    )
    return 0
