"""One design: the observer (:mod:`synthesis.design`), the controller's candidates simulated
and verified (:mod:`design.controller`), the designed scenario's certified gains, design.json.

The designed scenario is the scenario file with the design's keys as overrides, named
``<name>-designed`` (``out/<name>-designed/``): its gains.json (with its certificate), its
design.json and design.md sit there, and ``make demo`` runs it
(docs/synthesis.md, 'Design').
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import OUT_ROOT, atomic_write_text
from core.errors import ToolkitError
from core.scenario import Scenario
from design.controller import (
    GammaPoint,
    Point,
    assemble,
    candidate_overrides,
    candidates,
    choose,
    choose_gamma,
    disturbance_overrides,
    evaluate,
    gamma_candidates,
    health_bound,
)

#: the suffix of the designed scenario's name
VARIANT = "designed"
#: design.json's format
FORMAT = 1
#: largest design.json read back
MAX_DESIGN_BYTES = 16 * 2**20
#: the sources of the design procedure: a design.json written by another version of them
#: is designed again, not reused (:func:`procedure_sha256`)
PROCEDURE = ("design", "synthesis/design.py")


class DesignError(ToolkitError):
    """A design cannot be made: no ``[design]`` table, or a specification no gains meet."""


@dataclass(frozen=True)
class DesignResult:
    """A finished design.

    Attributes
    ----------
    base : Scenario
        The scenario designed for (with the user's overrides).
    overrides : dict
        The design's keys (observer and controller), as ``--set`` takes them.
    observer : synthesis.design.ObserverDesign
    given : Point
        The scenario's own gains, simulated and verified.
    points : list of Point
        Every candidate of the controller's grid.
    designed : Point
        The designed gains' confirmation run.
    chosen : list of Point
        Per follower, the candidate whose level it took.
    seconds : float
        Wall time of the design.
    gammas : list of GammaPoint
        The ĝ law's γ candidates (the first: the scenario's own γ).
    """

    base: Scenario
    overrides: dict[str, Any]
    observer: Any
    given: Point
    points: list[Point]
    designed: Point
    chosen: list[Point]
    seconds: float
    gammas: list[GammaPoint] = field(default_factory=list)


def variant_of(user_variant: str | None, user_overrides: dict[str, Any] | None) -> str:
    """The designed scenario's name suffix (after the user's own variant, if any).

    Parameters
    ----------
    user_variant : str or None
        ``--variant`` of the command line.
    user_overrides : dict or None
        ``--set`` of the command line.
    """
    if not user_overrides:
        return VARIANT
    from core.overrides import variant_label

    return f"{user_variant or variant_label(user_overrides)}-{VARIANT}"


def _budget(sc: Scenario) -> np.ndarray:
    return np.asarray(sc.design.u_max, float)


def _refuse_budget(sc: Scenario, points: list[Point], i: int) -> DesignError:
    """The one-line refusal when no candidate keeps follower ``i`` within its budget."""
    least = min(points, key=lambda p: p.peak[i])
    ok = [p for p in points if p.holds and p.covered_all and p.complete]
    hint = f"u_max >= {math.ceil(min(p.peak[i] for p in ok) * 10) / 10:g}" if ok else "a budget"
    return DesignError(
        f"{sc.path}: design.u_max: {float(_budget(sc)[i]):g} for follower {i + 1} is below "
        f"every candidate's peak |u_{i + 1}| after {sc.design.startup:g} s (least "
        f"{least.peak[i]:.4g} with k1 = {least.k1:g}, Lambda = {least.lam:g}); "
        f"use {hint} or a longer design.startup"
    )


def make_design(
    path: str | Path,
    user_overrides: dict[str, Any] | None = None,
    user_variant: str | None = None,
    *,
    out_root: Path | None = None,
    progress: bool = True,
) -> DesignResult:
    """Design the gains of the scenario at ``path`` for its ``[design]`` table.

    Parameters
    ----------
    path : str or Path
        The scenario file.
    user_overrides, user_variant
        ``--set`` and ``--variant`` of the command line.
    out_root : Path, optional
        Output root (default ``out/``).
    progress : bool
        One line per stage on stdout.

    Returns
    -------
    DesignResult

    Raises
    ------
    DesignError
        No ``[design]`` table, or a torque budget no candidate meets (one line naming
        ``design.u_max`` and what would work).
    """
    from generated import api
    from synthesis.design import observer_design

    t0 = time.perf_counter()
    root = Path(out_root or OUT_ROOT)
    user = dict(user_overrides or {})
    base = api.load(path, user or None, user_variant if user else None)
    if base.design is None:
        raise DesignError(
            f"{path}: has no [design] table: add one with at least u_max (the torque budget), "
            "docs/scenario-format.md, '[design]'"
        )
    say = print if progress else (lambda *a, **k: None)
    od = observer_design(base)
    obs = od.overrides()
    say(
        f"[design] observer: delta1 = {od.delta1:.4g}, delta2 = {od.delta2:.4g} "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    given, points = _grid(path, base, user, obs, root)
    say(
        f"[design] {len(points)} controller candidates simulated and verified "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    variant = variant_of(user_variant, user)
    ctrl, designed, chosen = _settle(path, base, user, variant, obs, points, root)
    ctrl, designed, gammas = _gamma(path, base, user, variant, obs, ctrl, designed, root)
    say(
        f"[design] {len(gammas)} gamma candidates simulated and verified "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    return DesignResult(
        base=base,
        overrides={**obs, **ctrl},
        observer=od,
        given=given,
        points=points,
        designed=designed,
        chosen=chosen,  # type: ignore[arg-type]
        seconds=time.perf_counter() - t0,
        gammas=gammas,
    )


def _gamma(
    path: str | Path,
    base: Scenario,
    user: dict,
    variant: str,
    obs: dict,
    ctrl: dict,
    designed: Point,
    root: Path,
) -> tuple[dict, Point, list[GammaPoint]]:
    """The ĝ law's γ_i (:func:`design.controller.choose_gamma`), confirmed by one run; the
    scenario's own γ when the assembled γ_i break the budget or a row."""
    from generated import api

    spec, budget = base.design, _budget(base)
    pts = []
    for k, gamma in enumerate(gamma_candidates(base)):
        ov = {**user, **obs, **ctrl, "controller.gamma": gamma}
        sc = api.load(path, ov, f"{variant}-gamma{k}")
        p = designed  # the first candidate is the scenario's γ: the run just confirmed
        if k:
            name, nan = f"{variant}-gamma{k}", math.nan
            p = evaluate(path, ov, name, "gamma", nan, nan, spec.startup, root)
        pts.append(GammaPoint(gamma, p, [health_bound(sc, i) for i in range(base.N)]))
    chosen = choose_gamma(pts, budget)
    gamma = [pts[0].gamma[i] if c is None else c.gamma[i] for i, c in enumerate(chosen)]
    if gamma == pts[0].gamma:
        return ctrl, designed, pts
    out = {**ctrl, "controller.gamma": gamma}
    final = evaluate(
        path, {**user, **obs, **out}, variant, "designed", math.nan, math.nan, spec.startup, root
    )
    if final.within(budget) and final.holds and final.covered_all and final.complete:
        return out, final, pts
    return ctrl, designed, pts


def _grid(
    path: str | Path, base: Scenario, user: dict, obs: dict, root: Path
) -> tuple[Point, list[Point]]:
    """The scenario's own gains and every candidate of the grid, simulated and verified."""
    spec = base.design
    k0, l0 = float(np.max(base.controller.k1)), float(np.max(base.controller.Lambda))
    given = evaluate(path, user, "given", "given", k0, l0, spec.startup, root)
    points = []
    for k, (k1, lam) in enumerate(candidates(base)):
        ov = {**user, **obs, **candidate_overrides(base, k1, lam)}
        points.append(evaluate(path, ov, f"candidate{k}", "candidate", k1, lam, spec.startup, root))
    return given, points


def _settle(
    path: str | Path,
    base: Scenario,
    user: dict,
    variant: str,
    obs: dict,
    points: list[Point],
    root: Path,
) -> tuple[dict, Point, list[Point]]:
    """Each follower's level (:func:`design.controller.choose`), confirmed by one run; one
    common level by the same rule when the assembled levels break the budget or a row."""
    spec, budget = base.design, _budget(base)
    chosen = choose(points, budget, spec.bound_slack)
    for i, c in enumerate(chosen):
        if c is None:
            raise _refuse_budget(base, points, i)
    ctrl = {**assemble(base, chosen), **disturbance_overrides(base)}  # type: ignore[arg-type]
    designed = evaluate(
        path, {**user, **obs, **ctrl}, variant, "designed", math.nan, math.nan, spec.startup, root
    )
    if designed.within(budget) and designed.holds and designed.covered_all:
        return ctrl, designed, chosen  # type: ignore[return-value]
    # the followers' levels interact through the graph: fall back to one common level
    common = [p for p in points if p.within(budget) and p.holds and p.covered_all]
    if not common:
        raise _refuse_budget(base, points, int(np.argmax(np.asarray(designed.peak) - budget)))
    best = min(p.bound for p in common)
    p = min(
        (q for q in common if q.bound <= spec.bound_slack * best),
        key=lambda q: (q.tc_max, q.bound),
    )
    return candidate_overrides(base, p.k1, p.lam), p, [p] * base.N


def write_design(
    d: DesignResult,
    user: dict[str, Any],
    user_variant: str | None,
    out_root: Path | None = None,
) -> Path:
    """Write the designed scenario's gains.json (certified), design.json and the report.

    Parameters
    ----------
    d : DesignResult
    user, user_variant
        The command line's overrides and variant.
    out_root : Path, optional

    Returns
    -------
    Path
        The designed scenario's folder.
    """
    from core.provenance import provenance
    from design.report import write_report
    from generated import api

    root = Path(out_root or OUT_ROOT)
    sc = api.load(d.base.path, {**user, **d.overrides}, variant_of(user_variant, user))
    folder = root / sc.name
    api.ensure_gains(sc, root)  # gains.json with its certificate, re-certified on every read
    prov = provenance()
    record = {
        "format": FORMAT,
        "scenario_sha256": d.base.sha256,
        "scenario_path": d.base.path,
        "procedure_sha256": procedure_sha256(),
        "user_overrides": user,
        "overrides": d.overrides,
        "designed_scenario": sc.name,
        "seconds": round(d.seconds, 2),
        "provenance": {"date": prov.date, "commit": prov.commit, "machine": prov.machine},
        "given": d.given.to_json(),
        "designed": d.designed.to_json(),
        "points": [p.to_json() for p in d.points],
        "gammas": [g.to_json() for g in d.gammas],
    }
    write_report(d, folder, prov)
    atomic_write_text(folder / "design.json", json.dumps(record, indent=1) + "\n")
    return folder


def procedure_sha256() -> str:
    """SHA-256 of the design procedure's sources (:data:`PROCEDURE`), by content only.

    Returns
    -------
    str
        Hex digest over the sources' relative names and bytes (the same in every checkout
        of the same code).
    """
    import hashlib

    top = Path(__file__).resolve().parent.parent
    files = []
    for name in PROCEDURE:
        p = top / name
        files += sorted(p.glob("*.py")) if p.is_dir() else [p]
    h = hashlib.sha256()
    for p in files:
        h.update(p.relative_to(top).as_posix().encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def stored_overrides(
    path: str | Path, user: dict[str, Any], user_variant: str | None, out_root: Path | None
) -> dict[str, Any] | None:
    """The design's keys from a design.json written for this very scenario by this very
    design procedure (:func:`procedure_sha256`), else None.

    Parameters
    ----------
    path : str or Path
        The scenario file.
    user, user_variant
        The command line's overrides and variant.
    out_root : Path, optional
    """
    from core.files import read_regular_file
    from generated import api

    base = api.load(path, user or None, user_variant if user else None)
    f = Path(out_root or OUT_ROOT) / f"{base.name}-{VARIANT}" / "design.json"
    try:
        rec = json.loads(read_regular_file(f, MAX_DESIGN_BYTES).decode("utf-8"))
    except (OSError, ValueError, ToolkitError):
        return None
    if not isinstance(rec, dict) or rec.get("format") != FORMAT:
        return None
    if rec.get("scenario_sha256") != base.sha256 or not isinstance(rec.get("overrides"), dict):
        return None
    if rec.get("procedure_sha256") != procedure_sha256():
        return None
    return rec["overrides"]
