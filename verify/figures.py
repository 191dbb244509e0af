"""The paper's figures reproduced from a trajectory DataFrame (PNG and PDF).

Figs. 3–10: formation snapshots (leader output y0 = C0η0, followers' p_i, the
desired slots y0 + b_i and the formation shape); Fig. 11: estimation errors
ē_ηi; Fig. 12: tracking errors e_ti; Fig. 13: eq. (42) ablation against the
fault-tolerant controller on the same axes; plus an animated GIF of the formation
when Pillow is importable.
"""

from __future__ import annotations

import importlib.util
import io
from pathlib import Path

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_bytes
from core.pyplot import pyplot
from verify import signals as S

plt = pyplot()  # files only, never a window

SNAPSHOTS = (0.0, 1.0, 3.0, 5.0, 10.0, 13.0, 17.0, 20.0)  # Figs. 3–10
# the followers are the paper's two-link arms: p_i are joint angles
POS_UNIT = "rad"
COLORS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def _save(fig: plt.Figure, folder: Path, stem: str) -> list[Path]:
    """Write ``stem.png`` and ``stem.pdf`` atomically."""
    out = []
    for ext in ("png", "pdf"):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, dpi=130 if ext == "png" else None, bbox_inches="tight")
        out.append(atomic_write_bytes(folder / f"{stem}.{ext}", buf.getvalue()))
    plt.close(fig)
    return out


def _index_at(t: np.ndarray, when: float) -> int:
    return int(np.argmin(np.abs(t - when)))


def _ring_order(offsets: np.ndarray) -> np.ndarray:
    """Agents sorted by the angle of their formation offset: draws the shape as a polygon."""
    return np.argsort(np.arctan2(offsets[:, 1], offsets[:, 0]))


def _formation_axes(ax, view: S.TrajectoryView, C0: np.ndarray, k: int, N: int) -> None:  # noqa: ANN001
    t = view.t
    y0 = view.leader_output(C0)
    ax.plot(
        y0[: k + 1, 0], y0[: k + 1, 1], "k-", lw=0.8, alpha=0.5, label="leader output y0 (path)"
    )
    ax.plot(y0[k, 0], y0[k, 1], "k*", ms=12, label="leader y0 = C0 eta0")
    P = np.array([view.block(S.Signal.P, i + 1)[k] for i in range(N)])
    slots = np.array([y0[k] + view.block(S.Signal.B, i + 1)[k] for i in range(N)])
    for i in range(N):
        c = COLORS[i % len(COLORS)]
        ax.plot(*view.block(S.Signal.P, i + 1)[: k + 1, :2].T, "-", color=c, lw=0.6, alpha=0.4)
        ax.plot(P[i, 0], P[i, 1], "o", color=c, ms=7, label=f"follower {i + 1} p_{i + 1}")
        ax.plot(slots[i, 0], slots[i, 1], "s", mfc="none", color=c, ms=9)
    order = _ring_order(slots - y0[k])
    ring = np.vstack([slots[order], slots[order[:1]]])
    ax.plot(ring[:, 0], ring[:, 1], "k--", lw=0.8, label="desired shape y0 + b_i")
    ringp = np.vstack([P[order], P[order[:1]]])
    ax.plot(ringp[:, 0], ringp[:, 1], "-", color="tab:gray", lw=1.0, label="followers' shape")
    ax.set_title(f"t = {t[k]:.2f} s")
    ax.set_xlabel(f"position component 1 ({POS_UNIT})")
    ax.set_ylabel(f"position component 2 ({POS_UNIT})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)


def formation_snapshots(
    df: pd.DataFrame, C0: np.ndarray, folder: Path, times: tuple[float, ...] = SNAPSHOTS
) -> list[Path]:
    """Figs. 3–10: one file per snapshot time plus an overview grid.

    Parameters
    ----------
    df : DataFrame
        Trajectory.
    C0 : ndarray
        Leader output matrix (y0 = C0 η0).
    folder : Path
        ``out/<name>/figures``.
    times : tuple of float
        Snapshot times (clipped to the horizon).

    Returns
    -------
    list of Path
    """
    view = S.TrajectoryView.of(df)
    dm, t = view.dims, view.t
    times = tuple(x for x in times if x <= t[-1] + 1e-9) or (float(t[-1]),)
    out: list[Path] = []
    for j, when in enumerate(times):
        fig, ax = plt.subplots(figsize=(5.5, 5))
        _formation_axes(ax, view, C0, _index_at(t, when), dm.N)
        ax.legend(fontsize=7, loc="best")
        out += _save(fig, folder, f"fig{3 + j:02d}_formation_t{when:g}")
    cols = 4
    rows = int(np.ceil(len(times) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * rows), squeeze=False)
    for ax, when in zip(axes.flat, times, strict=False):
        _formation_axes(ax, view, C0, _index_at(t, when), dm.N)
    for ax in list(axes.flat)[len(times) :]:
        ax.axis("off")
    h, lab = axes.flat[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle("Formation snapshots (Figs. 3-10): circles p_i, squares y0 + b_i")
    fig.tight_layout(rect=(0, 0.06 if rows > 1 else 0.14, 1, 0.97))  # room for the legend
    out += _save(fig, folder, "fig03-10_formation_overview")
    return out


def _per_agent_plot(view, sig, width, ylabel, title, folder, stem, log=False) -> list[Path]:  # noqa: ANN001
    dm, t = view.dims, view.t
    fig, axes = plt.subplots(width, 1, figsize=(7, 2.6 * width), sharex=True, squeeze=False)
    for r in range(width):
        ax = axes[r, 0]
        for i in range(dm.N):
            y = view.block(sig, i + 1, width)[:, r]
            c = COLORS[i % len(COLORS)]
            ax.plot(t, np.abs(y) if log else y, color=c, lw=1.1, label=f"follower {i + 1}")
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(ylabel.format(r=r + 1))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=min(dm.N, 5))
    axes[-1, 0].set_xlabel("time t (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, folder, stem)


def estimation_errors(df: pd.DataFrame, folder: Path) -> list[Path]:
    """Fig. 11: ē_ηi = η_i − η0 per component (linear) and |ē_ηi| (log).

    Parameters
    ----------
    df : DataFrame
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    folder : Path
        Folder the figure files are written to.
    """
    view = S.TrajectoryView.of(df)
    dm = view.dims
    out = _per_agent_plot(
        view,
        S.Signal.EETA,
        dm.m,
        "ebar_eta,{r} (state units)",
        "Fig. 11: estimation errors ebar_eta_i = eta_i - eta0",
        folder,
        "fig11_estimation_errors",
    )
    out += _per_agent_plot(
        view,
        S.Signal.EETA,
        dm.m,
        "|ebar_eta,{r}| (log)",
        "Fig. 11 (log scale)",
        folder,
        "fig11_estimation_errors_log",
        log=True,
    )
    return out


def tracking_errors(df: pd.DataFrame, folder: Path) -> list[Path]:
    """Fig. 12: e_ti = p_i − C0η_i − b_i per component (linear) and |e_ti| (log).

    Parameters
    ----------
    df : DataFrame
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    folder : Path
        Folder the figure files are written to.
    """
    view = S.TrajectoryView.of(df)
    dm = view.dims
    out = _per_agent_plot(
        view,
        S.Signal.ET,
        dm.n,
        f"e_t,{{r}} ({POS_UNIT})",
        "Fig. 12: tracking errors e_ti = p_i - C0 eta_i - b_i",
        folder,
        "fig12_tracking_errors",
    )
    out += _per_agent_plot(
        view,
        S.Signal.ET,
        dm.n,
        f"|e_t,{{r}}| ({POS_UNIT}, log)",
        "Fig. 12 (log scale)",
        folder,
        "fig12_tracking_errors_log",
        log=True,
    )
    return out


def ablation_comparison(df: pd.DataFrame, ablation: pd.DataFrame, folder: Path) -> list[Path]:
    """Fig. 13: ‖e_ti‖ of the fault-tolerant controller (29) and the ablation (42), same axes.

    Parameters
    ----------
    df : DataFrame
        The fault-tolerant run's trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    ablation : DataFrame
        The ablation run's trajectory (eq. (42)), same format.
    folder : Path
        Folder the figure files are written to.
    """
    fv, av = S.TrajectoryView.of(df), S.TrajectoryView.of(ablation)
    dm = fv.dims
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for ax, log in zip(axes, (False, True), strict=True):
        for i in range(dm.N):
            c = COLORS[i % len(COLORS)]
            ax.plot(
                fv.t,
                fv.norm(S.Signal.ET, i + 1, dm.n),
                "-",
                color=c,
                lw=1.2,
                label=f"FTC (29), follower {i + 1}",
            )
            ax.plot(
                av.t,
                av.norm(S.Signal.ET, i + 1, dm.n),
                "--",
                color=c,
                lw=1.2,
                label=f"ablation (42), follower {i + 1}",
            )
        ax.set_xlabel("time t (s)")
        ax.set_ylabel(f"|e_ti| ({POS_UNIT})" + (" (log)" if log else ""))
        if log:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2)
    fig.suptitle("Fig. 13: fault-tolerant controller (solid) vs ablation u_i = Psi_i (dashed)")
    fig.tight_layout()
    return _save(fig, folder, "fig13_ablation")


def lyapunov_figures(theorem1: list, theorem2: list, folder: Path) -> list[Path]:
    """The pointwise Lyapunov checks: margin rhs − V̇ (≥ 0 where the inequality holds).

    Parameters
    ----------
    theorem1, theorem2 : list of verify.lyapunov.InequalityCheck
    folder : Path

    Returns
    -------
    list of Path
    """
    out: list[Path] = []
    for checks, stem, title in (
        (theorem1, "lyapunov_V1", "Theorem 1: margin -delta~ V1 - dV1/dt (>= 0: holds)"),
        (theorem2, "lyapunov_V2", "Theorem 2: margin of eq. (38) (>= 0: holds)"),
    ):
        if not checks:
            continue
        fig, ax = plt.subplots(figsize=(7, 3.8))
        for k, chk in enumerate(checks):
            label = chk.claim if chk.agent is None else f"follower {chk.agent + 1}"
            ax.plot(chk.t, chk.rhs - chk.lhs, color=COLORS[k % len(COLORS)], lw=1.0, label=label)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_yscale("symlog", linthresh=1e-3)
        lo = min(float(np.min(c.rhs - c.lhs)) for c in checks)
        ax.set_ylim(bottom=min(-1e-2, 2.0 * lo))
        ax.set_xlabel("time t (s)")
        ax.set_ylabel("margin (units of V per s)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        out += _save(fig, folder, stem)
    return out


def animation(
    df: pd.DataFrame, C0: np.ndarray, folder: Path, frames: int = 60
) -> tuple[Path | None, str]:
    """Animated GIF of the formation (PillowWriter); skipped with a note without Pillow.

    Parameters
    ----------
    df : DataFrame
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    C0 : ndarray
        n×m leader output matrix (the formation is drawn around y0 = C0η0).
    folder : Path
        Folder the figure files are written to.
    frames : int
        Number of frames, sampled evenly over the trajectory.

    Returns
    -------
    (path or None, note)
    """
    if importlib.util.find_spec("PIL") is None:
        return None, "animation skipped: Pillow is not importable"
    from matplotlib.animation import FuncAnimation, PillowWriter

    view = S.TrajectoryView.of(df)
    dm, t = view.dims, view.t
    idx = np.unique(np.linspace(0, len(t) - 1, frames).round().astype(int))
    y0 = view.leader_output(C0)
    P = np.stack([view.block(S.Signal.P, i + 1)[:, :2] for i in range(dm.N)], axis=1)
    B = np.stack([view.block(S.Signal.B, i + 1)[:, :2] for i in range(dm.N)], axis=1)
    slots = y0[:, None, :2] + B
    allpts = np.concatenate([P.reshape(-1, 2), slots.reshape(-1, 2)])
    lo, hi = allpts.min(axis=0) - 1, allpts.max(axis=0) + 1
    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel(f"position component 1 ({POS_UNIT})")
    ax.set_ylabel(f"position component 2 ({POS_UNIT})")
    ax.grid(alpha=0.3)
    (lead,) = ax.plot([], [], "k*", ms=12, label="leader y0")
    (fol,) = ax.plot([], [], "o", color="tab:blue", ms=7, label="followers p_i")
    (slot,) = ax.plot([], [], "s", mfc="none", color="tab:red", ms=9, label="slots y0 + b_i")
    (shape,) = ax.plot([], [], "k--", lw=0.8)
    title = ax.set_title("")
    ax.legend(fontsize=8, loc="upper right")

    def draw(k: int):  # noqa: ANN202
        lead.set_data([y0[k, 0]], [y0[k, 1]])
        fol.set_data(P[k, :, 0], P[k, :, 1])
        slot.set_data(slots[k, :, 0], slots[k, :, 1])
        o = _ring_order(B[k])
        ring = np.vstack([slots[k, o], slots[k, o[:1]]])
        shape.set_data(ring[:, 0], ring[:, 1])
        title.set_text(f"formation, t = {t[k]:.2f} s")
        return lead, fol, slot, shape, title

    anim = FuncAnimation(fig, draw, frames=list(idx), blit=False)
    path = folder / "formation.gif"
    tmp = folder / ".formation.gif.tmp.gif"
    anim.save(tmp, writer=PillowWriter(fps=10))
    plt.close(fig)
    tmp.replace(path)  # atomic: the GIF writer needs a real file name, then rename
    return path, "animation written"


def all_figures(
    df: pd.DataFrame,
    C0: np.ndarray,
    folder: Path,
    ablation: pd.DataFrame | None = None,
    *,
    gif: bool = True,
) -> tuple[list[Path], list[str]]:
    """Every figure; returns the files written and notes (e.g. a skipped animation).

    Parameters
    ----------
    df : DataFrame
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    C0 : ndarray
        n×m leader output matrix.
    folder : Path
        Folder the figure files are written to.
    ablation : DataFrame, optional
        The ablation run's trajectory; Fig. 13 is skipped without it.
    gif : bool
        Also write the animation.
    """
    folder.mkdir(parents=True, exist_ok=True)
    files = formation_snapshots(df, C0, folder)
    files += estimation_errors(df, folder)
    files += tracking_errors(df, folder)
    notes: list[str] = []
    if ablation is not None:
        files += ablation_comparison(df, ablation, folder)
    else:
        notes.append("Fig. 13 skipped: no ablation run")
    if gif:
        p, note = animation(df, C0, folder)
        notes.append(note)
        if p is not None:
            files.append(p)
    return files, notes
