"""What sets the step count: steps per time window, and how they move with the model's knobs.

What drives the integrator's step count is measured, not guessed. Two measurements:

Windows (:func:`step_profile`)
    The horizon is cut into windows (finer near t = 0); each window is integrated by
    the same :func:`generated.solvers.engine.integrate` as ``make sim`` and its steps,
    error-test and Newton failures, last step size and order are recorded, together
    with whether the operator's command u0 changes sign inside the window. Each
    window restarts the integrator (order 1, small first step), so the windowed total
    is a few per cent above one uninterrupted run; the difference is printed.
Knobs (:func:`knob_sensitivity`)
    The whole run repeated with one scenario field changed (``--vary KEY=V1,V2,...``,
    the keys of ``python -m generated sim --set``): total steps, RHS evaluations,
    integration time, completion and the tail tracking errors. A diagnostic only:
    the shipped scenarios are not changed by it (the chosen values and why are in
    ``scenarios/paper.toml`` and docs/closed-loop.md).

``python -m benchmarks.steps [SCENARIO] [--bench-n N] [--vary KEY=V1,V2 ...] [--out DIR]``
prints both tables and writes ``steps_windows.csv`` and ``steps_knobs.csv``
(default folder ``out/steps/<scenario name>/``; the variants' gains go to its
``variants/`` subfolder). ``make bench`` runs it on the paper
scenario after the benchmark.
"""

from __future__ import annotations

import dataclasses
import math
import time
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count
from core.errors import CliParser, IntegrationError, UsageError, run_cli
from core.provenance import write_provenance
from core.scenario import METHODS

PAPER = Path(__file__).resolve().parent.parent / "scenarios" / "paper.toml"
#: the knobs varied by default: the tanh boundary layer, the φ floor of the observer's
#: sign-like term, and the speed below which the formation angle fades out
DEFAULT_VARY = (
    ("options.sign_width", (0.01, 0.05, 0.2)),
    ("observer.phi_min", (0.001, 0.005, 0.05)),
    ("options.tau_threshold", (0.1, 0.5, 2.0)),
)


@dataclass(frozen=True)
class Window:
    """One window of a step profile.

    Attributes
    ----------
    start, end : float
        The window [s].
    steps, rhs_evals, error_test_fails, newton_fails : int
        CVODES counters over the window.
    last_step : float
        Last step size taken in the window (s); NaN if unknown.
    u0_sign_change : bool
        True when some component of the operator's command u0 changes sign inside.
    since_u0_sign_change : float
        Time from the last sign change of u0 before the window's end to the window's
        start (negative: the change is inside the window; NaN: none yet).
    """

    start: float
    end: float
    steps: int
    rhs_evals: int
    error_test_fails: int
    newton_fails: int
    last_step: float
    u0_sign_change: bool
    since_u0_sign_change: float

    @property
    def steps_per_second(self) -> float:
        """Steps per simulated second."""
        return self.steps / (self.end - self.start)


def default_edges(horizon: float) -> np.ndarray:
    """Window edges: 0, 0.01, 0.03, 0.1, 0.3, 0.5, 1, 2, …, horizon (1 s after the start).

    Parameters
    ----------
    horizon : float
        Final time (s), > 0.
    """
    if not (math.isfinite(horizon) and horizon > 0):
        raise IntegrationError(f"horizon: {horizon!r} must be a number > 0")
    head = [e for e in (0.0, 0.01, 0.03, 0.1, 0.3, 0.5) if e < horizon]
    tail = list(np.arange(1.0, horizon, 1.0))
    return np.array(sorted({*head, *tail, float(horizon)}))


def u0_sign_change_times(sc: Any, horizon: float, step: float = 1e-3) -> np.ndarray:
    """Times (to ``step``) where a component of the leader's input u0 changes sign.

    Parameters
    ----------
    sc : Scenario
    horizon : float
        End of the search (s).
    step : float
        Sampling step (a sign change between two samples counts, at the later one).
    """
    from symbolic.leader import leader_function

    lead = leader_function(sc.leader)
    n = max(2, int(round(horizon / step)) + 1)
    t = np.linspace(0.0, horizon, n)
    u = np.array(lead.map(n)(t.reshape(1, -1), np.zeros((sc.m, n)))[5]).reshape(-1, n)
    s = np.sign(u)
    hit = np.any(s[:, 1:] * s[:, :-1] < 0, axis=0)
    return t[1:][hit]


def step_profile(built: Any, sc: Any, edges: Sequence[float], settings: Any = None) -> list[Window]:
    """Integrate window by window and record the solver's counters in each.

    Parameters
    ----------
    built : generated.built.Built
        The compiled closed loop (ODE form).
    sc : Scenario
    edges : sequence of float
        Increasing window edges starting at 0.
    settings : IntegratorSettings, optional
        Default :func:`generated.api.integrator_settings` of ``sc``.

    Returns
    -------
    list of Window

    Raises
    ------
    IntegrationError
        If a window fails (the message names the window).
    """
    from generated import api

    e = np.asarray(edges, dtype=float)
    if e.ndim != 1 or len(e) < 2 or e[0] != 0.0 or np.any(np.diff(e) <= 0):
        raise IntegrationError("edges: must increase strictly from 0 (e.g. 0, 0.1, 1, 2)")
    s = settings or api.integrator_settings(sc)
    s = dataclasses.replace(s, chunk=float(e[-1]))  # one integrator call per window
    bps = api.breakpoints(built, sc)
    x = np.asarray(built.closed_loop.x0, dtype=float)
    changes = u0_sign_change_times(sc, float(e[-1]))
    out = []
    for a, b in zip(e[:-1], e[1:], strict=True):
        tr = api.integrate_built(built, x, np.array([a, b]), s, bps)
        if not tr.complete:
            raise IntegrationError(f"step profile, window [{a:g}, {b:g}] s: {tr.message}", a)
        x = tr.x[-1]
        st = tr.stats
        before = changes[changes <= b]
        since = float(a - before[-1]) if len(before) else math.nan
        out.append(
            Window(
                float(a),
                float(b),
                int(st["steps"]),
                int(st["rhs_evals"]),
                int(st["error_test_fails"]),
                int(st["newton_fails"]),
                float(st.get("last_step", math.nan)),
                bool(np.any((changes > a) & (changes <= b))),
                since,
            )
        )
    return out


def windows_frame(windows: Sequence[Window]) -> pd.DataFrame:
    """The windows as a table (one row per window, with steps per second).

    Parameters
    ----------
    windows : sequence of Window
        From :func:`step_profile`.
    """
    rows = [{**dataclasses.asdict(w), "steps_per_s": w.steps_per_second} for w in windows]
    return pd.DataFrame(rows)


def _tail_errors(built: Any, traj: Any, fraction: float = 0.25) -> tuple[float, float]:
    """Max of |η_i − η0| and |e_t| over the last ``fraction`` of the run, all agents and
    components (the "tail" of docs/closed-loop.md: [15, 20] s for 20 s)."""
    from generated.api import evaluate_outputs
    from verify.signals import tail_mask

    k = tail_mask(traj.t, fraction)
    lay = built.closed_loop.layout
    x = traj.x[k]
    eta0 = lay.get(x, "eta0")
    eeta = max(np.abs(lay.get(x, "eta", i) - eta0).max() for i in range(lay.N))
    et = evaluate_outputs(built, traj)["et"][k]
    return float(eeta), float(np.abs(et).max())


def knob_sensitivity(
    path: str | Path,
    vary: Sequence[tuple[str, Sequence[Any]]],
    out_root: str | Path | None = None,
    codegen: Any = None,
    method: str | None = None,
) -> pd.DataFrame:
    """Whole runs with one field changed at a time: steps, time, completion, tail errors.

    Parameters
    ----------
    path : str or Path
        Scenario file.
    vary : sequence of (key, values)
        Dotted scenario keys (as for ``--set``) and the values to try; the file's own
        value is run once as ``(file)``.
    out_root : str or Path, optional
        Where gains of the variants are cached (default ``out/``).
    codegen : CodegenSettings, optional
        Compiler settings (default: those of ``make sim``).
    method : str, optional
        Integration method (default: the scenario's).

    Returns
    -------
    pandas.DataFrame
        ``key, value, steps, rhs_evals, integration_s, complete, t_reached,
        tail_eeta, tail_et`` (tails: max over the last quarter of the horizon, all
        followers and components).
    """
    from generated import api

    runs: list[tuple[str, Any, dict[str, Any]]] = [("(file)", "", {})]
    runs += [(k, v, {k: v}) for k, vals in vary for v in vals]
    rows = []
    for key, value, ov in runs:
        sc = api.with_method(api.load(path, ov or None, variant=None), method)
        gains, _ = api.ensure_gains(sc, out_root)
        built = api.build(sc, gains, settings=codegen)
        t0 = time.perf_counter()
        tr = api.simulate(built, sc)
        wall = time.perf_counter() - t0
        eeta, et = _tail_errors(built, tr) if tr.complete else (math.nan, math.nan)
        rows.append(
            dict(
                key=key,
                value=value,
                steps=tr.stats["steps"],
                rhs_evals=tr.stats["rhs_evals"],
                integration_s=wall,
                complete=tr.complete,
                t_reached=tr.t_reached,
                tail_eeta=eeta,
                tail_et=et,
            )
        )
    return pd.DataFrame(rows)


def parse_vary(text: str) -> tuple[str, tuple[Any, ...]]:
    """``KEY=V1,V2,...`` -> ``(KEY, (V1, V2, ...))`` with TOML values.

    Parameters
    ----------
    text : str
        As given to ``--vary``.

    Raises
    ------
    UsageError
        Not ``KEY=V1,...`` or a value that is not a TOML scalar.
    """
    key, sep, vals = text.partition("=")
    if not sep or not key.strip() or not vals.strip():
        raise UsageError(
            f"--vary {text!r}: expected KEY=V1,V2,... (e.g. observer.phi_min=0.001,0.05)"
        )
    try:
        values = tuple(tomllib.loads(f"v = [{vals}]")["v"])
    except tomllib.TOMLDecodeError:
        raise UsageError(
            f"--vary {text!r}: values must be TOML scalars separated by commas"
        ) from None
    return key.strip(), values


def main(argv: list[str]) -> int:
    """``python -m benchmarks.steps``: print and write the window and knob tables.

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.

    Returns
    -------
    int
        0, or 2 on a toolkit error (one line on stderr).
    """
    from generated import api

    ap = CliParser(prog="python -m benchmarks.steps", description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", nargs="?", default=str(PAPER), help="scenario (default paper)")
    ap.add_argument(
        "--bench-n",
        type=count,
        default=None,
        help="profile the benchmark's N-follower scenario instead (no knob table)",
    )
    ap.add_argument(
        "--vary",
        action="append",
        default=None,
        metavar="KEY=V1,V2",
        help="knob to vary (repeatable); default sign_width, phi_min, tau_threshold",
    )
    ap.add_argument(
        "--method",
        choices=METHODS,
        default=None,
        help="integration method (default: the scenario's; cvodes = through CasADi)",
    )
    ap.add_argument("--no-knobs", action="store_true", help="window profile only")
    ap.add_argument("--out", default=None, help="output folder (default out/steps/<name>)")
    args = ap.parse_args(argv)
    vary = [parse_vary(v) for v in args.vary] if args.vary else list(DEFAULT_VARY)

    if args.bench_n is not None:
        from benchmarks.scenarios import bench_gains, bench_scenario

        sc = bench_scenario(args.bench_n)
        gains, _ = bench_gains(sc)
    else:
        sc = api.load(args.scenario)
        gains, _ = api.ensure_gains(sc)
    sc = api.with_method(sc, args.method)
    built = api.build(sc, gains)
    folder = Path(args.out) if args.out else Path(OUT_ROOT) / "steps" / sc.name
    write_provenance(folder)  # (creates the folder)
    edges = default_edges(sc.integration.horizon)
    wins = step_profile(built, sc, edges)
    one = api.simulate(built, sc, dataclasses.replace(api.integrator_settings(sc), chunk=1e9))
    wf = windows_frame(wins)
    atomic_write_text(folder / "steps_windows.csv", wf.to_csv(index=False))
    print(f"step profile: {sc.name} (N = {sc.N}), {len(wins)} windows")
    print(wf.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    tot = int(wf["steps"].sum())
    near = wf["since_u0_sign_change"] < 1.0  # the change is inside or < 1 s before the window
    flagged = int(wf.loc[near, "steps"].sum())
    early = int(wf.loc[wf["end"] <= 0.3, "steps"].sum())
    print(
        f"windows total {tot} steps (one uninterrupted run: {one.stats['steps']}); "
        f"t < 0.3 s (start-up): {early} ({100 * early / max(tot, 1):.0f} %); windows that "
        f"contain a sign change of u0 or start < 1 s after one: {flagged} "
        f"({100 * flagged / max(tot, 1):.0f} %) in {int(near.sum())} of {len(wf)} windows"
    )
    if args.bench_n is None and not args.no_knobs:
        kf = knob_sensitivity(args.scenario, vary, out_root=folder / "variants", method=args.method)
        atomic_write_text(folder / "steps_knobs.csv", kf.to_csv(index=False))
        print("\nknob sensitivity (whole runs, one field changed; a diagnostic, not a tuning):")
        print(kf.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"wrote {folder}/steps_windows.csv" + ("" if args.no_knobs else " and steps_knobs.csv"))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
