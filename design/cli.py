"""``python -m design run|demo SCENARIO`` (``make design``, ``make demo``).

- ``run``: design the gains of a scenario with a ``[design]`` table and write, in
  ``out/<name>-designed/``, gains.json (with its certificate), design.json and design.md
  with the fronts (docs/synthesis.md, 'Design').
- ``demo``: ``python -m verify demo`` on the scenario; with a ``[design]`` table, on its
  designed gains (designed first unless a design.json written for this scenario by this
  version of the design procedure exists).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from core.artifacts import OUT_ROOT
from core.errors import CliParser, UsageError
from core.overrides import add_scenario_knobs, scenario_knobs

DEFAULT_SCENARIO = "scenarios/paper-design.toml"


def _parser() -> CliParser:
    ap = CliParser(prog="python -m design", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("run", help="design the gains of a scenario's [design] table")
    p.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    p.add_argument("--out", default=None, help="output root (default out/ or $HITL_OUT)")
    add_scenario_knobs(p)
    return ap


def _set_args(overrides: dict) -> list[str]:
    """The overrides as ``--set KEY=VALUE`` arguments (values as TOML through JSON)."""
    out = []
    for k, v in overrides.items():
        out += ["--set", f"{k}={json.dumps(v)}"]
    return out


def demo(argv: list[str]) -> int:
    """``verify demo`` on the scenario, or on its designed gains when it has ``[design]``.

    Parameters
    ----------
    argv : list of str
        The arguments of ``python -m verify demo`` (scenario, --set, --variant, ...).
    """
    import argparse

    from generated import api
    from verify.__main__ import main as verify_main

    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("scenario", nargs="?", default="scenarios/paper.toml")
    ap.add_argument("--out", default=None)
    add_scenario_knobs(ap)
    known, _ = ap.parse_known_args(argv)
    if not Path(known.scenario).is_file():
        return verify_main(["demo", *argv])  # verify names the missing file
    user, user_variant = scenario_knobs(known)
    base = api.load(known.scenario, user, user_variant)
    if base.design is None:
        return verify_main(["demo", *argv])
    from design.run import make_design, stored_overrides, variant_of, write_design

    root = Path(known.out) if known.out else OUT_ROOT
    ov = stored_overrides(known.scenario, user or {}, user_variant, root)
    if ov is None:
        d = make_design(known.scenario, user, user_variant, out_root=root)
        write_design(d, user or {}, user_variant, root)
        ov = d.overrides
    else:
        print(
            f"[design] reusing the design of {base.name} (design.json: this scenario, this procedure)"
        )
    rest, skip = [], False
    for a in argv:  # the designed run's variant replaces the user's
        if skip:
            skip = False
        elif a == "--variant":
            skip = True
        elif not a.startswith("--variant="):
            rest.append(a)
    variant = variant_of(user_variant, user)
    return verify_main(["demo", *rest, *_set_args(ov), "--variant", variant])


def main(argv: list[str]) -> int:
    """Entry point; returns the exit status.

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.
    """
    if argv and argv[0] == "demo":
        return demo(argv[1:])
    args = _parser().parse_args(argv)
    if not Path(args.scenario).is_file():
        raise UsageError(f"scenario {args.scenario!r} does not exist: give a TOML file path")
    from design.run import make_design, write_design

    user, user_variant = scenario_knobs(args)
    root = Path(args.out) if args.out else OUT_ROOT
    d = make_design(args.scenario, user, user_variant, out_root=root)
    folder = write_design(d, user or {}, user_variant, root)
    p, g = d.designed, d.given
    print(
        f"designed {d.base.name} in {d.seconds:.1f} s: time to the guarantee max t_c "
        f"{p.tc_max:.3g} s (the scenario's gains: {g.tc_max:.3g} s), coverage {p.coverage:.0%} "
        f"({g.coverage:.0%}), ultimate bound {p.bound:.3g} ({g.bound:.3g}), peak |u_i| after "
        f"{d.base.design.startup:g} s {p.peak_max:.4g} ({g.peak_max:.4g})"
    )
    print(f"gains: {folder / 'gains.json'}\nreport: {folder / 'design.md'}")
    sys.stdout.flush()
    return 0
