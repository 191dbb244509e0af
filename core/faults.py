"""Fault library: abrupt, gradual, intermittent loss of effectiveness and bias faults.

A follower's ``[[followers.faults]]`` tables each describe one fault. A loss of
effectiveness multiplies the actuator health by a factor h_k(t) in (0, 1]; a bias
fault adds a step to the disturbance. The faulted signals are

    g_i(t) = g_i,base(t) * prod_k h_k(t)        f_i(t) = f_i,base(t) + sum_k a_k step(t - onset_k)

built as :class:`~core.expressions.Expr` node trees (never text to be evaluated),
so the closed loop (CasADi), the reference (numpy) and the breakpoint search all
see the same function. Every fault is right-continuous: at a switching time it
already takes its new value (``step(0) = 1``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from core.expressions import Expr
from core.settings import NONNEG, POSITIVE, REQUIRED, Check, Derived, Setting, declare

SEVERITY = Check(
    "in [0, 1)",
    lambda x: (x >= 0) & (x < 1),
    "{v} is outside [0, 1)",
    "0 <= severity < 1 (the fraction of effectiveness lost; health stays in (0, 1])",
)
DUTY = Check(
    "in (0, 1)",
    lambda x: (x > 0) & (x < 1),
    "{v} is outside (0, 1)",
    "0 < duty < 1 (the fraction of each period the fault is on)",
)

#: the keys of one ``[[followers.faults]]`` table (docs/scenario-format.md, 'Faults')
FAULT: dict[str, Setting] = {
    "type": declare(REQUIRED, "string"),
    "onset": declare(REQUIRED, "number", NONNEG),
    "severity": declare(Derived("required (abrupt, ramp, intermittent)"), "number", SEVERITY),
    "duration": declare(Derived("required (ramp)"), "number", POSITIVE),
    "period": declare(Derived("required (intermittent)"), "number", POSITIVE),
    "duty": declare(Derived("required (intermittent)"), "number", DUTY),
    "amplitude": declare(Derived("required (bias)"), "vector", dims=("n", "")),
}
#: the keys each fault type takes (all of them required)
FAULT_TYPES: dict[str, tuple[str, ...]] = {
    "abrupt": ("type", "onset", "severity"),
    "ramp": ("type", "onset", "severity", "duration"),
    "intermittent": ("type", "onset", "severity", "period", "duty"),
    "bias": ("type", "onset", "amplitude"),
}
MAX_SWITCHES = 1000  # on/off switches of one intermittent fault before the horizon


@dataclass(frozen=True)
class Fault:
    """One fault of a follower, as read from a ``[[followers.faults]]`` table.

    Attributes
    ----------
    type : str
        ``"abrupt"``, ``"ramp"``, ``"intermittent"`` or ``"bias"``.
    onset : float
        Time the fault starts, in [0, horizon].
    severity : float
        Fraction of effectiveness lost, in [0, 1) (health faults).
    duration : float
        Length of the ramp (``"ramp"``).
    period, duty : float
        On/off period and the fraction of it the fault is on (``"intermittent"``).
    amplitude : tuple of float
        Bias added to each component of f_i (``"bias"``).
    """

    type: str
    onset: float
    severity: float = 0.0
    duration: float = 0.0
    period: float = 0.0
    duty: float = 0.0
    amplitude: tuple[float, ...] = ()

    @property
    def is_bias(self) -> bool:
        """True for a bias fault (acts on f_i), False for a loss of effectiveness (on g_i)."""
        return self.type == "bias"

    def times(self, horizon: float) -> tuple[float, ...]:
        """The times where the fault switches or kinks (ramp start and end, every on/off).

        Parameters
        ----------
        horizon : float
            End of the run; intermittent pulses starting at or after it are dropped.
        """
        if self.type == "ramp":
            return (self.onset, self.onset + self.duration)
        if self.type == "intermittent":
            return tuple(t for pulse in self.pulses(horizon) for t in pulse)
        return (self.onset,)

    def pulses(self, horizon: float) -> tuple[tuple[float, float], ...]:
        """``(on, off)`` of each pulse of an intermittent fault that starts before ``horizon``.

        Pulse k is on over [onset + k period, onset + k period + duty period).

        Parameters
        ----------
        horizon : float
            End of the run.
        """
        count = pulse_count(self.onset, self.period, horizon)
        starts = (self.onset + k * self.period for k in range(count))
        return tuple((on, on + self.duty * self.period) for on in starts)

    def factor(self, horizon: float) -> tuple:
        """The node of the health factor h(t) in [1 - severity, 1] (not for a bias fault).

        Parameters
        ----------
        horizon : float
            End of the run (bounds the pulses of an intermittent fault).
        """
        if self.type == "abrupt":
            lost = _step_at(self.onset)
        elif self.type == "ramp":  # 0 before onset, linear to 1 at onset + duration
            rise = ("bin", "/", ("bin", "-", ("t",), ("num", self.onset)), ("num", self.duration))
            lost = ("call", "min", (("call", "max", (rise, ("num", 0.0))), ("num", 1.0)))
        else:
            pulses = [("bin", "-", _step_at(on), _step_at(off)) for on, off in self.pulses(horizon)]
            lost = balanced("+", pulses) if pulses else ("num", 0.0)
        return ("bin", "-", ("num", 1.0), ("bin", "*", ("num", self.severity), lost))

    def describe(self) -> str:
        """One readable line: the type and its parameters."""
        if self.type == "bias":
            amp = ", ".join(f"{a:g}" for a in self.amplitude)
            return f"bias [{amp}] from t = {self.onset:g}"
        text = f"{self.type} loss {self.severity:g} from t = {self.onset:g}"
        if self.type == "ramp":
            text += f" over {self.duration:g} s"
        if self.type == "intermittent":
            text += f", period {self.period:g} s, duty {self.duty:g}"
        return text


def pulse_count(onset: float, period: float, horizon: float) -> int:
    """Number of pulses ``onset + k period`` (k = 0, 1, ...) strictly before ``horizon``.

    Parameters
    ----------
    onset, period, horizon : float
        The pulse train and the end of the run (``period > 0``).
    """
    if onset >= horizon:
        return 0
    count = math.ceil((horizon - onset) / period)
    while count > 0 and onset + (count - 1) * period >= horizon:
        count -= 1  # rounding of the ceil above
    while onset + count * period < horizon:
        count += 1
    return count


def faulted_health(base: Expr, faults: tuple[Fault, ...], horizon: float) -> Expr:
    """g(t) = g_base(t) times the factor of every loss-of-effectiveness fault.

    Parameters
    ----------
    base : Expr
        The follower's own ``g`` (constant, table or expression).
    faults : tuple of Fault
        The follower's faults; bias faults are skipped.
    horizon : float
        End of the run.
    """
    factors = [fa.factor(horizon) for fa in faults if not fa.is_bias]
    if not factors:
        return base
    return _expr(("bin", "*", base.node, balanced("*", factors)))


def faulted_bias(base: tuple[Expr, ...], faults: tuple[Fault, ...]) -> tuple[Expr, ...]:
    """f_r(t) = f_base,r(t) plus ``amplitude[r] step(t - onset)`` of every bias fault.

    Parameters
    ----------
    base : tuple of Expr
        The follower's own ``f``, one per component.
    faults : tuple of Fault
        The follower's faults; loss-of-effectiveness faults are skipped.
    """
    biases = [fa for fa in faults if fa.is_bias]
    if not biases:
        return base
    out = []
    for r, e in enumerate(base):
        steps = [("bin", "*", ("num", fa.amplitude[r]), _step_at(fa.onset)) for fa in biases]
        out.append(_expr(("bin", "+", e.node, balanced("+", steps))))
    return tuple(out)


def balanced(op: str, terms: list[tuple]) -> tuple:
    """``terms`` joined by ``op`` (``"+"`` or ``"*"``) as a balanced tree (shallow for long lists).

    Parameters
    ----------
    op : str
        An associative operator.
    terms : list of tuple
        Expression nodes, at least one.
    """
    if len(terms) == 1:
        return terms[0]
    mid = len(terms) // 2
    return ("bin", op, balanced(op, terms[:mid]), balanced(op, terms[mid:]))


def node_text(node: tuple) -> str:
    """The node as fully parenthesised text that parses back to the same function.

    The text names the expression (the closed loop shares evaluations of equal texts).

    Parameters
    ----------
    node : tuple
        An :class:`~core.expressions.Expr` node.
    """
    kind = node[0]
    if kind == "num":
        return repr(node[1]) if node[1] >= 0 else f"({node[1]!r})"
    if kind == "t":
        return "t"
    if kind == "neg":
        return f"(-{node_text(node[1])})"
    if kind == "bin":
        return f"({node_text(node[2])} {node[1]} {node_text(node[3])})"
    return f"{node[1]}({', '.join(node_text(a) for a in node[2])})"


def _expr(node: tuple) -> Expr:
    return Expr(node_text(node), node)


def _step_at(t0: float) -> tuple:
    """``step(t - t0)``: 0 before ``t0``, 1 from ``t0`` on."""
    return ("call", "step", (("bin", "-", ("t",), ("num", t0)),))
