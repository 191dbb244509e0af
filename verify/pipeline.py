"""The verification pipeline behind ``python -m verify check|report|demo``.

Stages that are missing or stale (their ``scenario_sha256`` differs from the
scenario's) are produced through :mod:`generated.api` (which runs the synthesis
when needed); fresh artifacts are reused. The Lyapunov checks need the symbolic
closed loop and the states: the states come from the simulation run itself or,
when ``trajectory.csv`` is reused, are read back from its state columns
(:func:`states_from_frame`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.artifacts import OUT_ROOT
from core.scenario import Scenario
from verify import signals as S
from verify.bounds import VerifyConfig, VerifyError, theorem1_floor, theorem1_rates
from verify.intervals import u0_dependence
from verify.lyapunov import check_theorem1, closed_loop
from verify.report import Verification, ablation_statement
from verify.table import bounds_table
from verify.theorem2_check import check_theorem2

ABLATION = {"options.ablation": True}


@dataclass
class Run:
    """One simulated scenario: its frame, states (if known), metadata and folder.

    ``gains`` are the gains the run used when the caller holds them (certified for this
    scenario by :func:`generated.api.ensure_gains` in this process); None: the checks
    read ``<out_root>/<name>/gains.json`` and re-certify it. ``closed_loop`` is the loop
    the run integrated (bound to this scenario and ``gains``), when the caller holds it;
    the checks use it with those gains instead of binding the numbers again.
    """

    scenario: Scenario
    frame: pd.DataFrame
    X: np.ndarray | None
    meta: dict[str, Any]
    folder: Path
    simulated: bool = False
    notes: list[str] = field(default_factory=list)
    gains: Any = None
    closed_loop: Any = None


def states_from_frame(cl: Any, sc: Scenario, df: pd.DataFrame) -> np.ndarray:
    """Rebuild the state matrix (K, nx) from the state columns of ``trajectory.csv``.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    sc : Scenario
        The scenario (m, for the leader's columns).
    df : DataFrame
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).

    Raises
    ------
    VerifyError
        If the layout has states the CSV does not store (the derivative filters).
    """
    lay = cl.layout
    view = S.TrajectoryView.of(df)
    X = np.full((len(view), lay.nx), np.nan)
    for key, sl in lay.slices.items():
        try:
            if key == "eta0":
                X[:, sl] = view.leader(sc.m)
            else:
                name, i = key
                X[:, sl] = view.block(S.Signal.named(name), i + 1, sl.stop - sl.start)
        except VerifyError:  # a state the CSV does not store, or one of its columns missing
            raise VerifyError(
                f"trajectory.csv does not store state {key!r}: re-simulate (verify demo) "
                "to check the Lyapunov inequalities"
            ) from None
    return X


def _fresh(folder: Path, sc: Scenario) -> dict | None:
    """meta.json of ``folder`` if its run may be reused for ``sc`` (else None).

    Parameters
    ----------
    folder : Path
        ``out/<name>/``.
    sc : Scenario
        The scenario.
    """
    from generated import api

    why, found = api.reuse_problem(folder, sc)
    return None if why is not None else found[0]


def obtain_run(
    path: str | Path,
    overrides: dict | None = None,
    *,
    variant: str | None = None,
    out_root: Path | None = None,
    force: bool = False,
    progress: bool = True,
) -> Run:
    """Reuse ``out/<name>/trajectory.csv`` if fresh, else simulate (and synthesize) it.

    Fresh means :func:`generated.api.reuse_problem` finds nothing: same scenario,
    trace data, gains file, method, code, CasADi and library hashes, a complete run,
    and a CSV with the SHA-256 and row count meta.json records. Otherwise the reason
    is printed on stderr and the scenario is simulated again.

    Parameters
    ----------
    path : str or Path
        Scenario file.
    overrides : dict, optional
        E.g. :data:`ABLATION`.
    variant : str, optional
        Name suffix of the overridden run (:func:`generated.api.load`).
    out_root : Path, optional
    force : bool
        Simulate even when a fresh trajectory exists.
    progress : bool
        Progress bar on stderr.

    Returns
    -------
    Run
    """
    from generated import api

    root = Path(out_root or OUT_ROOT)
    sc = api.load(path, overrides, variant)
    folder = root / sc.name
    # the derivative filters' states are not in trajectory.csv: such runs are always re-simulated
    reusable = not force and sc.options.derivatives != "filtered"
    if reusable:
        # reused only when every input matches and the CSV is the one meta.json describes
        why, found = api.reuse_problem(folder, sc)
        if why is None:
            meta, data = found
            df, _ = api.read_trajectory(data)  # the bytes whose SHA-256 was checked
            return Run(sc, df, None, meta, folder, simulated=False)
        if why != "no previous run":
            print(f"{folder / 'trajectory.csv'}: not reused ({why}); simulating")
    res = api.run(path, overrides=overrides, variant=variant, out_root=root, progress=progress)
    return Run(sc, res.frame, res.trajectory.x, res.meta, folder, simulated=True)


def _lyapunov_checks(run: Run, gains, cfg: VerifyConfig):
    """The exact V̇1, V̇2 inequality checks and the u0 dependence of ``run``'s closed loop."""
    sc = run.scenario
    cl = run.closed_loop if run.gains is not None else None
    cl = cl or closed_loop(sc, gains)  # the symbolic loop is built once per structure
    X = run.X if run.X is not None else states_from_frame(cl, sc, run.frame)
    t = run.frame["t"].to_numpy(float)
    rates = theorem1_rates(sc, gains)
    t1 = [
        check_theorem1(
            cl, t, X, rates.supported, claim="dV1/dt <= -delta~ V1 (supported)", config=cfg
        ),
        check_theorem1(cl, t, X, rates.printed, claim="dV1/dt <= -delta~ V1 (printed)", config=cfg),
    ]
    if sc.observer.phi_min > 0:  # the inequality the proof gives with the floor
        fl = theorem1_floor(sc, gains)
        claim = "dV1/dt <= -delta~ V1 + c_phi (floor)"
        t1.append(check_theorem1(cl, t, X, fl.rate, offset=fl.c_phi, claim=claim, config=cfg))
    t2 = check_theorem2(cl, sc, t, X, config=cfg)
    u0_dep = u0_dependence(cl, sc)
    return t1, t2, u0_dep


def verify_run(
    run: Run,
    *,
    ablation: Run | None = None,
    config: VerifyConfig | None = None,
    out_root: Path | None = None,
    lyapunov: bool = True,
) -> Verification:
    """Theorem 1/2 checks and the bound-vs-actual table for a run.

    Parameters
    ----------
    run : Run
    ablation : Run, optional
        The eq. (42) run, for Fig. 13.
    config : VerifyConfig, optional
    out_root : Path, optional
    lyapunov : bool
        Whether to evaluate the exact V̇1, V̇2 inequalities (needs the closed loop).

    Returns
    -------
    Verification
    """
    from generated import api

    cfg = config or VerifyConfig()
    sc = run.scenario
    root = Path(out_root or OUT_ROOT)
    gains = run.gains if run.gains is not None else api.ensure_gains(sc, root)[0]
    notes = list(run.notes)
    t1, t2, u0_dep = [], [], None
    if lyapunov:
        t1, t2, u0_dep = _lyapunov_checks(run, gains, cfg)
    else:
        notes.append("Lyapunov derivative checks skipped (--no-lyapunov)")
    if not run.meta.get("complete", True):
        notes.append(f"simulation incomplete: {run.meta.get('message', '')}")
    table = bounds_table(
        sc,
        run.frame,
        gains=gains,
        theorem1=t1,
        theorem2=t2,
        ablation=None if ablation is None else ablation.frame,
        config=cfg,
        u0_dep=u0_dep,
    )
    meta = dict(run.meta)
    ws = meta.get("wall_seconds")
    if isinstance(ws, dict):
        meta["wall_seconds"] = round(float(ws.get("total", math.nan)), 2)
    from verify.headline import run_numbers
    from verify.table import STARTUP, gauge

    numbers = run_numbers(sc, run.frame, gauge(sc, gains), cfg.tail_fraction, STARTUP)
    return Verification(
        numbers=numbers,
        scenario=sc,
        table=table,
        gains=gains,
        theorem1=t1,
        theorem2=t2,
        ablation_summary=ablation_statement(table),
        notes=notes,
        meta=meta,
        config=cfg,
    )
