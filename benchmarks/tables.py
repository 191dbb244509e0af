"""The benchmark's results: the finished records, bench.csv, the table, bench.md and the plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.catalogue import METHODS, ours_method

COLUMNS = [
    "N",
    "nx",
    "method",
    "plan",
    "status",
    "runs",
    "int_median_s",
    "int_min_s",
    "int_max_s",
    "ratio_to_ours",
    "symbolic_s",
    "codegen_s",
    "compile_s",
    "cache_hit",
    "c_bytes",
    "steps",
    "rhs_evals",
    "jac_evals",
    "jtimes_evals",
    "rhs_us",
    "peak_rss_mb",
    "base_rss_mb",
    "t_reached",
    "rel_dx_final_vs_ours",
    "gains",
]


def finish(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Add the ratio to ours and the final-state difference to ours, per N.

    Parameters
    ----------
    records : list of dict
        Cell records (changed in place and returned).
    """
    for N in sorted({r["N"] for r in records}):
        ours_name = ours_method(N)
        ours = next((r for r in records if r["N"] == N and r["method"] == ours_name), None)
        for r in records:
            if r["N"] != N:
                continue
            r["ours"] = r["method"] == ours_name
            ok = r.get("status") == "ok"
            if ours and ours.get("status") == "ok" and ours.get("int_median_s") and ok:
                r["ratio_to_ours"] = r["int_median_s"] / ours["int_median_s"]
            xa, xb = r.get("_x_final"), (ours or {}).get("_x_final")
            complete = ok and (ours or {}).get("status") == "ok"
            if complete and xa is not None and xb is not None and xa.shape == xb.shape:
                r["rel_dx_final_vs_ours"] = float(
                    np.max(np.abs(xa - xb) / np.maximum(1.0, np.abs(xb)))
                )
    return records


def write_csv(records: list[dict[str, Any]], path: Path) -> Path:
    """``bench.csv`` (atomically).

    Parameters
    ----------
    records : list of dict
        Cell records.
    path : Path
        The CSV file.
    """
    import csv
    import io

    from core.artifacts import atomic_write_text

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(COLUMNS)
    for r in records:
        w.writerow([_fmt_csv(r.get(c)) for c in COLUMNS])
    return atomic_write_text(path, buf.getvalue())


def _fmt_csv(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def table(records: list[dict[str, Any]]) -> str:
    """The printed table.

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    """
    head = (
        "N",
        "method",
        "int med [s]",
        "min–max [s]",
        "×ours",
        "steps",
        "RHS ev",
        "µs/RHS",
        "sym [s]",
        "cg+cc [s]",
        "C [kB]",
        "RSS [MB]",
        "status",
    )
    rows = [head]
    for r in records:
        med = r.get("int_median_s")
        mm = f"{r['int_min_s']:.3g}–{r['int_max_s']:.3g}" if med is not None else ""
        cgcc = (r.get("codegen_s") or 0.0) + (r.get("compile_s") or 0.0)
        star = "*" if r.get("ours") else ""
        rows.append(
            (
                str(r["N"]),
                r["method"] + star,
                short_number(med),
                mm,
                short_number(r.get("ratio_to_ours")),
                short_number(r.get("steps")),
                short_number(r.get("rhs_evals")),
                short_number(r.get("rhs_us")),
                short_number(r.get("symbolic_s")),
                short_number(cgcc) if "codegen_s" in r else "",
                short_number((r.get("c_bytes") or 0) / 1000) if r.get("c_bytes") else "",
                short_number(r.get("peak_rss_mb")),
                status_short(r),
            )
        )
    widths = [max(len(row[k]) for row in rows) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return (
        "\n".join(lines)
        + "\n(* = ours: what make sim runs for N, benchmarks.catalogue.ours_method)"
    )


def markdown(records: list[dict[str, Any]]) -> str:
    """The results as a Markdown table (``out/bench/bench.md``, for the README).

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    """
    head = [
        "N",
        "method",
        "integration [s] median (min–max)",
        "× ours",
        "steps",
        "RHS evals",
        "µs / RHS",
        "symbolic [s]",
        "codegen + gcc [s]",
        "C [kB]",
        "peak RSS [MB]",
        "status",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        med = r.get("int_median_s")
        t = f"{med:.3g} ({r['int_min_s']:.3g}–{r['int_max_s']:.3g})" if med is not None else ""
        cgcc = (r.get("codegen_s") or 0.0) + (r.get("compile_s") or 0.0)
        cells = [
            str(r["N"]),
            r["method"] + (" *" if r.get("ours") else ""),
            t,
            short_number(r.get("ratio_to_ours")),
            short_number(r.get("steps")),
            short_number(r.get("rhs_evals")),
            short_number(r.get("rhs_us")),
            short_number(r.get("symbolic_s")),
            short_number(cgcc) if "codegen_s" in r else "",
            short_number(r["c_bytes"] / 1000) if r.get("c_bytes") else "",
            short_number(r.get("peak_rss_mb")),
            status_short(r).replace("|", "/"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def status_short(r: dict[str, Any]) -> str:
    """A record's status with its runs note, for the progress lines and the table.

    Parameters
    ----------
    r : dict
        A cell record.
    """
    s = str(r.get("status", ""))
    note = r.get("runs_note")
    return f"{s} [{note}]" if note else s


def short_number(v: Any) -> str:
    """A number in three significant digits (empty for None or a non-finite float).

    Parameters
    ----------
    v : object
    """
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, int):
        return str(v)
    return f"{v:.3g}"


def plot(records: list[dict[str, Any]], path: Path) -> Path | None:
    """``scaling.png``: integration time against N (log-log), one line per method.

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    path : Path
        The PNG file.
    """
    import io

    from core.artifacts import atomic_write_bytes
    from core.pyplot import pyplot

    plt = pyplot()

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for meth in METHODS:
        mine = [r for r in records if r["method"] == meth]
        pts = [
            (r["N"], r["int_median_s"])
            for r in mine
            if r.get("status") == "ok" and r.get("int_median_s")
        ]
        # stopped or failed cells that ran (not the "not run" ones), at their wall time
        bad = [
            (r["N"], r["cell_wall_s"])
            for r in mine
            if r.get("status") != "ok"
            and r.get("cell_wall_s")
            and not str(r.get("status", "")).startswith(("not run", "build only"))
        ]
        if not pts and not bad:
            continue
        xy = list(zip(*sorted(pts), strict=True)) if pts else [[], []]
        (line,) = ax.loglog(*xy, "o-", label=meth)
        if bad:
            ax.loglog(*zip(*sorted(bad), strict=True), "x", color=line.get_color(), ms=8)
    Ns = sorted({r["N"] for r in records})
    if len(Ns) > 1:
        ax.loglog(Ns, [0.05 * n / Ns[0] for n in Ns], "k:", lw=0.8, label="∝ N")
    ax.set_xlabel("followers N")
    ax.set_ylabel("integration wall time, 20 s horizon [s]")
    ax.set_title("x: stopped at the time limit or failed (at the cell's wall time)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())
