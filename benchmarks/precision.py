"""Work against precision: how far each integrator is from the converged trajectory.

``python -m benchmarks.precision [SCENARIO] [--methods cvodes,native] [--rtols 1e-6,1e-8]
[--ref-rtol 1e-10] [--out out/precision]`` (also run by ``make bench``).

Speed means little without accuracy: two methods at the same nominal tolerance can
land at very different distances from the true trajectory. This module integrates the
scenario with every method at every tolerance (``atol`` keeps the scenario's
``atol/rtol`` ratio), and compares each run with a reference: the native integrator
at ``--ref-rtol``, itself checked against CasADi's CVODES at the same tolerance (the
two are independent implementations of the BDF solve; their distance is printed as
the reference's own uncertainty).

Errors are relative, per state and output time: ``|x − x_ref| / max(1, |x_ref|)``;
``max_err`` is the largest over the whole run, ``max_err_after_1s`` over t ≥ 1 s
(after the start-up transient), ``final_err`` at the horizon.

Writes ``<out>/<scenario>/precision.csv`` and prints the table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.errors import CliParser, UsageError, run_cli

DEFAULT_SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "paper.toml"
DEFAULT_METHODS = ("cvodes", "native")
DEFAULT_RTOLS = (1e-6, 1e-8)
REFERENCE_METHOD, CHECK_METHOD = "native", "cvodes"


def relative_errors(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``|x − ref| / max(1, |ref|)``, elementwise.

    Parameters
    ----------
    x, ref : ndarray
        Same shape.
    """
    return np.abs(x - ref) / np.maximum(1.0, np.abs(ref))


def precision_table(
    sc: Any,
    methods: Sequence[str] = DEFAULT_METHODS,
    rtols: Sequence[float] = DEFAULT_RTOLS,
    ref_rtol: float = 1e-10,
    *,
    codegen: Any = None,
    out_root: str | Path | None = None,
) -> tuple[pd.DataFrame, float]:
    """One row per (method, rtol): wall time, steps and errors against the reference.

    Parameters
    ----------
    sc : Scenario
    methods : sequence of str
        Integration methods (``cvodes``, ``native``, ``idas``, ``fixed``).
    rtols : sequence of float
        Relative tolerances; ``atol = rtol · (scenario atol / scenario rtol)``.
    ref_rtol : float
        Tolerance of the reference runs.
    codegen : CodegenSettings, optional
        Compiler settings and cache root of the builds.
    out_root : str or Path, optional
        Where the gains are found or synthesised (default ``out/``).

    Returns
    -------
    (DataFrame, float)
        The table and the reference's uncertainty (max relative distance between the
        native and CVODES reference runs).

    Raises
    ------
    IntegrationError
        If a reference run fails.
    """
    from generated import api

    gains, _ = api.ensure_gains(sc, out_root)
    ratio = sc.integration.atol / sc.integration.rtol
    builds: dict[str, Any] = {}

    def run(method: str, rtol: float):
        if method not in builds:
            builds[method] = api.build(sc, gains, method, codegen)
        s = api.integrator_settings(sc, method)
        s = dataclasses.replace(s, rtol=rtol, atol=rtol * ratio, max_steps=10**7)
        return api.simulate(builds[method], sc, s)

    ref = run(REFERENCE_METHOD, ref_rtol)
    ref.raise_if_incomplete()
    check = run(CHECK_METHOD, ref_rtol)
    check.raise_if_incomplete()
    uncertainty = float(relative_errors(check.x, ref.x).max())
    layout = builds[REFERENCE_METHOD].closed_loop.layout
    rows = []
    for method in methods:
        for rtol in rtols:
            tr = run(method, float(rtol))
            n = len(tr.t)
            e = relative_errors(tr.x, ref.x[:n])
            k, j = np.unravel_index(int(np.argmax(e)), e.shape)
            late = tr.t >= 1.0
            rows.append(
                {
                    "method": method,
                    "rtol": float(rtol),
                    "atol": float(rtol) * ratio,
                    "complete": tr.complete,
                    "wall_s": tr.stats["wall_seconds"],
                    "steps": tr.stats["steps"],
                    "rhs_evals": tr.stats["rhs_evals"],
                    "max_err": float(e.max()),
                    "worst_t": float(tr.t[k]),
                    "worst_state": layout.name_of(int(j)),
                    "max_err_after_1s": float(e[late].max()) if late.any() else np.nan,
                    "final_err": float(e[-1].max()) if tr.complete else np.nan,
                }
            )
    return pd.DataFrame(rows), uncertainty


def _floats(text: str, what: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise UsageError(f"{what}: {text!r} is not a comma-separated list of numbers") from None
    if not vals or any(not (np.isfinite(v) and 0 < v < 1) for v in vals):
        raise UsageError(f"{what}: {text!r} needs tolerances in (0, 1), e.g. 1e-6,1e-8")
    return vals


def main(argv: list[str] | None = None) -> int:
    """Command line: print and write the work–precision table.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status 0.
    """
    from core.artifacts import OUT_ROOT, atomic_write_text
    from core.scenario import METHODS
    from generated import api

    ap = CliParser(prog="python -m benchmarks.precision", description=__doc__)
    ap.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS))
    ap.add_argument("--rtols", default=",".join(f"{r:g}" for r in DEFAULT_RTOLS))
    ap.add_argument("--ref-rtol", default="1e-10")
    ap.add_argument("--out", default=str(Path(OUT_ROOT) / "precision"))
    a = ap.parse_args(argv)
    methods = tuple(m for m in a.methods.split(",") if m)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise UsageError(
            f"--methods: {', '.join(bad) or 'none given'} (expected some of {', '.join(METHODS)})"
        )
    rtols = _floats(a.rtols, "--rtols")
    (ref_rtol,) = _floats(a.ref_rtol, "--ref-rtol")
    sc = api.load(a.scenario)
    df, unc = precision_table(sc, methods, rtols, ref_rtol)
    path = Path(a.out) / sc.name / "precision.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, df.to_csv(index=False))
    from core.provenance import write_provenance

    write_provenance(path.parent)
    print(
        f"{sc.name}: reference = {REFERENCE_METHOD} at rtol {ref_rtol:g}; it differs from "
        f"{CHECK_METHOD} at the same tolerance by {unc:.2g} (relative, max over states and times)"
    )
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(df.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
