"""The operator's command u0, shaped: every change enters as a C¹ ramp, not a jump.

A change of the command from u to u' at time c enters as (u' − u)·S((t − c)/r), S the
smoothstep 3x² − 2x³ of ``leader.u0_rise`` (core/shaping.py) and r the rise time
(:data:`CONSOLE_RISE` = :data:`core.shaping.DEFAULT_RISE`, chosen for a reversal of 2α)
unless the console is given another. Ramps that overlap add up; the command is then a
convex blend of the values held (core/hold.py), so ‖u0‖ ≤ α holds for every command
the protocol accepts. At most :data:`RAMP_SLOTS` ramps run at once (the compiled loop
has that many); a change asked for while all run waits for the oldest to end. The end
of a ramp (c + r, where its curvature jumps) is a breakpoint of the call that crosses it.

The command is a base (u0 with every finished ramp added) plus the running ramps; the
console scenario writes u0_k as ``a + Σ_j d_j*smoothstep((t - c_j)/r_j)`` and
:func:`u0_literals` gives those literals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.shaping import DEFAULT_RISE

#: rise time (s) of the console's shaped changes of u0: the scenarios' default. It was
#: chosen for the worst change an operator can make within α, a reversal from −α to +α
#: (docs/verification.md, 'Operator steps'), which is also the largest console change
#: (docs/console.md, 'Shaped commands')
CONSOLE_RISE = DEFAULT_RISE
#: ramps of u0 that may run at once (terms of the console scenario's u0 expressions)
RAMP_SLOTS = 12


@dataclass(frozen=True)
class Ramp:
    """One shaped change of u0: ``d · S((t − c)/r)``.

    Attributes
    ----------
    c : float
        Its start (the time the change landed).
    d : ndarray, shape (p,)
        The change.
    r : float
        Its rise time (s).
    """

    c: float
    d: np.ndarray
    r: float

    @property
    def end(self) -> float:
        """Where it reaches its full size (its curvature jumps)."""
        return self.c + self.r


def smoothstep(x: np.ndarray | float) -> np.ndarray:
    """3x² − 2x³ on [0, 1], 0 below, 1 above (core.expressions' ``smoothstep``).

    Parameters
    ----------
    x : float or ndarray
    """
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def command_at(base: np.ndarray, ramps: list[Ramp], t: float | np.ndarray) -> np.ndarray:
    """The shaped command at time(s) ``t``: the base plus every running ramp.

    Parameters
    ----------
    base : ndarray, shape (p,)
        u0 with every finished ramp added.
    ramps : list of Ramp
        The running ramps.
    t : float or ndarray
        Time(s); the result has shape (p,) for a scalar, (len(t), p) for an array.
    """
    t = np.asarray(t, dtype=float)
    u = np.broadcast_to(base, (*t.shape, base.size)).copy()
    for rp in ramps:
        u = u + smoothstep((t - rp.c) / rp.r)[..., None] * rp.d
    return u


def fold_finished(base: np.ndarray, ramps: list[Ramp], t: float) -> tuple[np.ndarray, list[Ramp]]:
    """The base and running ramps at ``t``: the ramps that ended by then join the base.

    Parameters
    ----------
    base : ndarray, shape (p,)
    ramps : list of Ramp
        Oldest first.
    t : float
        Now.
    """
    for rp in ramps:
        if rp.end <= t:  # constant from its end on
            base = base + rp.d
    return base, [rp for rp in ramps if rp.end > t]


def u0_literals(base: float, ramps: list[Ramp], k: int, rise: float) -> list[float]:
    """The literals of the console scenario's u0_k: ``a`` then (d_j, c_j, r_j) per slot.

    Parameters
    ----------
    base : float
        The base command's component k (``a``).
    ramps : list of Ramp
        The running ramps (at most :data:`RAMP_SLOTS`), oldest first.
    k : int
        The component of u0.
    rise : float
        The rise time written in an unused slot (its d is 0).
    """
    out = [base]
    for j in range(RAMP_SLOTS):
        rp = ramps[j] if j < len(ramps) else None
        out += (0.0, 0.0, rise) if rp is None else (rp.d[k], rp.c, rp.r)
    return out
