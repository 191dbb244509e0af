"""Link losses: where the kick of a switched link comes from, and the switching models compared.

::

    python -m benchmarks.links                      # the kick, then 6 samples per model
    python -m benchmarks.links --samples 12 --only raw fade-1

Part 1, **the kick** (docs/verification.md, 'Link losses'): the paper scenario with
follower 4 losing follower 2 at 5 s and hearing it again from 10 s, integrated with raw
switching (``graph.link_fade = 0``) and with the default fade. At the logged state of
each switch the closed loop's outputs are evaluated just before and at the switch time
(the same state, the old and the new weights): which of ψ_i (eq. (6)), ê_i (eq. (7)), v_i
(eq. (9)), the oracle's η̇_i, η̈_i, η⃛_i, the formation offset b_i and its derivatives, χ_i
and u_i (eqs. (28)-(29)) jump, and by how much; then the peak of each over the second
after the switch, raw and faded.

Part 2, **the switching models** on the first samples of ``studies/links.toml`` (same
seeds, graphs and losses for every model), each a ``[set]`` key on top of the study, run
by ``python -m sweep run`` (the layer above; only its command line is used) as
:mod:`benchmarks.remedies` does for operator steps: raw switching and fades over 0.25,
0.5, 1 and 2 s. Summarised from each ``results.parquet``: samples ``ok`` and stopped,
tail error, peak |u_i| after 1 s and its ratio to the same sample with its switches made
no-ops, integrator steps, the (switch, follower) pairs back within 0.05 of their slots
within 2 s, and the guaranteed rows held. Every model of one sample is one compiled
structure (the fade is a runtime parameter), shared with the study itself through the
build cache. Results: ``<out>/links.md`` (date, commit, machine, command) and
``<out>/links.csv``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.variants import (
    Variant,
    chosen,
    g,
    guaranteed_counts,
    nums,
    pair_counts,
    run_variant,
    stat,
    study_variant,
)
from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count, natural
from core.errors import CliParser, UsageError, run_cli
from core.graph import DEFAULT_LINK_FADE
from core.provenance import provenance_line

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STUDY = ROOT / "studies" / "links.toml"
PAPER = ROOT / "scenarios" / "paper.toml"
#: follower 4 (1-based) loses follower 2 at 5 s and hears it again from 10 s
KICK_SWITCHES = ((5.0, 4, 2, 0.0), (10.0, 4, 2, 1.0))
KICK_HORIZON = 14.0
#: the outputs followed through a switch, in the order of the chain
CHAIN = (
    ("psi", "ψ_i, eq. (6)"),
    ("ehat", "ê_i, eq. (7)"),
    ("v", "v_i, eq. (9)"),
    ("etadot", "η̇_i"),
    ("etaddot", "η̈_i (oracle)"),
    ("eta3dot", "η⃛_i (oracle)"),
    ("bdot", "ḃ_i"),
    ("bddot", "b̈_i"),
    ("chi", "χ_i, eq. (28)"),
    ("u", "u_i, eq. (29)"),
    ("V2", "V2_i, eq. (32)"),
)

#: the switching models compared, in the table's order
MODELS: tuple[Variant, ...] = (
    Variant("raw", {"graph.link_fade": 0.0}, "raw switching (`link_fade = 0`)"),
    *(
        Variant(f"fade-{T:g}", {"graph.link_fade": T}, f"fade over {T:g} s")
        for T in (0.25, 0.5, 1.0, 2.0)
    ),
)


# ----------------------------------------------------------------------------- part 1
def kick_scenario(folder: Path) -> Path:
    """The paper scenario with :data:`KICK_SWITCHES`, written to ``folder``.

    Parameters
    ----------
    folder : Path
    """
    text = PAPER.read_text(encoding="utf-8")
    anchor = "pinning = [1.0, 0.0, 0.0, 0.0, 0.0]\n"
    if text.count(anchor) != 1:
        raise UsageError(f"{PAPER}: its [graph] pinning line changed; update benchmarks.links")
    tables = "".join(
        f"\n[[graph.switches]]\ntime = {t}\nfollower = {i}\nneighbour = {j}\nweight = {w}\n"
        for t, i, j, w in KICK_SWITCHES
    )
    text = text.replace(anchor, anchor + tables).replace('name = "paper"', 'name = "paper-link"')
    folder.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(folder / "paper-link.toml", text)


def kick(folder: Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Part 1: the jumps at the same state and the peaks after each switch, raw and faded.

    Parameters
    ----------
    folder : Path
        Where the scenario and its runs go.

    Returns
    -------
    (rows, runs)
        One row per (switch, output): follower 4's norm before and at the switch (raw
        weights) and the peaks of followers 4 and 5 over [s, s + 1], raw and faded; and
        per model its integrator steps and completion.
    """
    from generated import api
    from verify.lyapunov import closed_loop, outputs_at

    path = kick_scenario(folder)
    base = {"integration.horizon": KICK_HORIZON}
    res, cls = {}, {}
    for key, fade in (("raw", 0.0), ("fade", DEFAULT_LINK_FADE)):
        ov = {**base, "graph.link_fade": fade}
        r = api.run(path, overrides=ov, out_root=folder / key, progress=False)
        sc = api.load(path, ov)
        gains, _ = api.ensure_gains(sc, folder / key)
        res[key], cls[key] = r, closed_loop(sc, gains)
    rows = []
    for s, *_ in KICK_SWITCHES:
        t, X = res["raw"].trajectory.t, res["raw"].trajectory.x
        k = int(np.argmin(np.abs(t - s)))
        at = outputs_at(cls["raw"], np.array([s - 1e-9, s]), np.vstack([X[k], X[k]]))
        peaks = {}
        for key in res:
            tt, XX = res[key].trajectory.t, res[key].trajectory.x
            w = (tt >= s) & (tt <= s + 1.0)
            peaks[key] = outputs_at(cls[key], tt[w], XX[w])
        for name, label in CHAIN:
            row = {"switch": s, "output": label}
            row["before"] = _norm(at[name][0], 3)
            row["after"] = _norm(at[name][1], 3)
            for key in res:
                for i in (3, 4):
                    v = peaks[key][name]
                    row[f"{key}_peak_{i + 1}"] = float(
                        max(_norm(v[j], i) for j in range(v.shape[0]))
                    )
            rows.append(row)
    runs = {
        key: {"steps": r.trajectory.stats.get("steps"), "complete": r.meta["complete"]}
        for key, r in res.items()
    }
    return rows, runs


def _norm(a: np.ndarray, i: int) -> float:
    """Follower i's Euclidean norm of a per-agent output (N rows), or the scalar V2_i."""
    a = np.asarray(a)
    return float(np.linalg.norm(a[i])) if a.ndim >= 1 and a.shape[0] > i else math.nan


# ----------------------------------------------------------------------------- part 2
def summarize(model: Variant, table: pd.DataFrame) -> dict[str, Any]:
    """One line of the comparison from a model's results.

    Parameters
    ----------
    model : Variant
    table : DataFrame
        Its ``results.parquet``.
    """
    ok = table[table["status"] == "ok"]
    status = table["status"].astype(str)
    ratio = nums(ok, "peak_u_late") / nums(ok, "peak_u_late_nolosses")
    return {
        "model": model.name,
        "what": model.what,
        "samples": int((~status.str.startswith("refused")).sum()),
        "ok": len(ok),
        "stopped": int(status.str.contains("IntegrationError").sum()),
        "tail_et_median": stat(nums(ok, "tail_max_et"), "median"),
        "tail_et_max": stat(nums(ok, "tail_max_et"), "max"),
        "peak_u_late_median": stat(nums(ok, "peak_u_late"), "median"),
        "peak_u_late_max": stat(nums(ok, "peak_u_late"), "max"),
        "ratio_median": stat(ratio, "median"),
        "ratio_max": stat(ratio, "max"),
        "steps_median": stat(nums(ok, "steps"), "median"),
        **pair_counts(ok, "switch"),
        **guaranteed_counts(ok),
    }


def markdown(
    kick_rows: list[dict[str, Any]],
    kick_runs: dict[str, Any],
    rows: list[dict[str, Any]],
    study: Path,
    count: int,
    command: str,
) -> str:
    """The report: provenance, the kick's chain, the models' table.

    Parameters
    ----------
    kick_rows, kick_runs
        From :func:`kick` (empty with ``--no-kick``).
    rows : list of dict
        From :func:`summarize`, in order.
    study : Path
    count : int
        Samples per model.
    command : str
    """
    out = ["# Link losses", "", f"{provenance_line()}; `{command}`.", ""]
    if kick_rows:
        out += [
            "## The kick",
            "",
            "The paper scenario, follower 4 loses follower 2 at 5 s and hears it again from "
            f"10 s (horizon {KICK_HORIZON:g} s). Before / at: follower 4's outputs at the logged "
            "state of the raw run at the switch, with the old and the new weights. Peaks: the "
            f"largest norm over [s, s + 1 s] for followers 4 and 5, raw and faded over "
            f"{DEFAULT_LINK_FADE:g} s (the default). Integrator steps: "
            + ", ".join(
                f"{k} {v['steps']} ({'complete' if v['complete'] else 'stopped'})"
                for k, v in kick_runs.items()
            )
            + ".",
            "",
            "| switch [s] | output | before | at (raw) | raw peak, 4 | raw peak, 5 "
            "| faded peak, 4 | faded peak, 5 |",
            "|---|---|---|---|---|---|---|---|",
        ]
        out += [
            f"| {r['switch']:g} | {r['output']} | {g(r['before'])} | {g(r['after'])} "
            f"| {g(r['raw_peak_4'])} | {g(r['raw_peak_5'])} | {g(r['fade_peak_4'])} "
            f"| {g(r['fade_peak_5'])} |"
            for r in kick_rows
        ]
        out.append("")
    if rows:
        out += [
            "## The switching models",
            "",
            f"The first {count} samples of `{study.name}` (same seeds, graphs and losses for "
            "every model; refused draws left out), each run by `python -m sweep run` with the "
            "model's key in `[set]`. Stopped: the integrator gave up. Tail error: max over "
            "followers of sup ‖e_ti‖ on the tail window; peak |u_i| after 1 s: max over "
            "followers; ratio: that peak over the same sample's with its switches made "
            "no-ops; back in 2 s: (switch, follower) pairs within 0.05 of the slot within 2 s "
            "(undefined: still out when the next switch or the horizon came within 2 s); "
            "guaranteed rows: the verification table's, pooled over the ok samples.",
            "",
            "| model | ok (stopped) | tail ‖e_t‖ median (max) | peak \\|u_i\\| after 1 s median "
            "(max) | ratio to no losses median (max) | steps (median) | back in 2 s "
            "(undefined) | guaranteed rows held |",
            "|---|---|---|---|---|---|---|---|",
        ]
        out += [
            f"| {r['what']} | {r['ok']}/{r['samples']} ({r['stopped']}) "
            f"| {g(r['tail_et_median'])} ({g(r['tail_et_max'])}) "
            f"| {g(r['peak_u_late_median'])} ({g(r['peak_u_late_max'])}) "
            f"| {g(r['ratio_median'])} ({g(r['ratio_max'])}) | {g(r['steps_median'])} "
            f"| {r['pairs_back']}/{r['pairs']} ({r['pairs_undefined']}) "
            f"| {r['guaranteed_held']}/{r['guaranteed_rows']} |"
            for r in rows
        ]
    return "\n".join(out) + "\n"


def _parser() -> argparse.ArgumentParser:
    p = CliParser(prog="python -m benchmarks.links", description=__doc__)
    p.add_argument("--study", type=Path, default=DEFAULT_STUDY, help="the link-loss study")
    p.add_argument(
        "--samples", type=natural, default=6, help="samples per model; 0: only the kick (default 6)"
    )
    p.add_argument("--workers", type=count, default=1, help="sweep workers (default 1)")
    p.add_argument("--only", nargs="+", metavar="NAME", help="only these models")
    p.add_argument("--no-kick", action="store_true", help="skip part 1")
    p.add_argument("--out", type=Path, default=OUT_ROOT / "link-models", help="output folder")
    return p


def main(argv: list[str]) -> int:
    """Run the kick and every model's variant study; write ``links.md`` and ``links.csv``.

    Parameters
    ----------
    argv : list of str
        Command-line arguments (without the program name).
    """
    a = _parser().parse_args(argv)
    models = chosen(MODELS, a.only, "model")
    kick_rows, kick_runs = ([], {}) if a.no_kick else kick(a.out / "kick")
    rows = []
    for model in models if a.samples else []:
        path = study_variant(a.study, model, a.samples, a.out / "studies")
        table = run_variant(path, a.out, a.workers)
        rows.append(summarize(model, table[table["id"] < a.samples]))  # a resumed larger run
        print(f"{model.name}: {rows[-1]['ok']}/{rows[-1]['samples']} ok", flush=True)
    command = ("python -m benchmarks.links " + " ".join(argv)).strip()
    if rows:
        atomic_write_text(a.out / "links.csv", pd.DataFrame(rows).to_csv(index=False))
    text = markdown(kick_rows, kick_runs, rows, a.study, a.samples, command)
    atomic_write_text(a.out / "links.md", text)
    print(f"report: {a.out / 'links.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
