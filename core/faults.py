"""Fault library: abrupt, gradual, intermittent loss of effectiveness and bias faults.

A follower's ``[[followers.faults]]`` tables each describe one fault. A loss of
effectiveness multiplies the actuator health by a factor h_k(t) in (0, 1]; a bias
fault adds a step to the disturbance. The faulted signals are

    g_i(t) = g_i,base(t) * prod_k h_k(t)        f_i(t) = f_i,base(t) + sum_k a_k step(t - onset_k)

built as :class:`~core.expressions.Expr` node trees (never text to be evaluated),
so the closed loop (CasADi), the reference (numpy) and the breakpoint search all
see the same function. Every fault is right-continuous: at a switching time it
already takes its new value (``step(0) = 1``).

By default each fault type has its own tree (:meth:`Fault.factor`). With
``options.fault_slots = K`` every follower's g_i and f_i are instead built from K
*slots* of one generic form (:class:`Slot`, :func:`slot_activation`), whatever the
faults: the trees then differ only in their numbers, so scenarios that differ in the
faults' types, followers, onsets or severities share one compiled closed loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.expression_tree import BinOp, Call, Neg, Node, Num, Time, Visitor, visit
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
MAX_SLOTS = 100  # options.fault_slots: as many as the faults one follower may have
SLOT_COUNT = Check(
    f"≤ {MAX_SLOTS}",
    lambda x: x <= MAX_SLOTS,
    "{v:g} slots are more than a follower may have faults",
    f"0 <= fault_slots <= {MAX_SLOTS}",
)


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

    def factor(self, horizon: float) -> Node:
        """The node of the health factor h(t) in [1 - severity, 1] (not for a bias fault).

        Parameters
        ----------
        horizon : float
            End of the run (bounds the pulses of an intermittent fault).
        """
        if self.type == "abrupt":
            lost = _step_at(self.onset)
        elif self.type == "ramp":  # 0 before onset, linear to 1 at onset + duration
            rise = BinOp("/", BinOp("-", Time(), Num(self.onset)), Num(self.duration))
            lost = Call("min", (Call("max", (rise, Num(0.0))), Num(1.0)))
        else:
            pulses = [BinOp("-", _step_at(on), _step_at(off)) for on, off in self.pulses(horizon)]
            lost = balanced("+", pulses) if pulses else Num(0.0)
        return BinOp("-", Num(1.0), BinOp("*", Num(self.severity), lost))

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
    return _expr(BinOp("*", base.node, balanced("*", factors)))


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
        steps = [BinOp("*", Num(fa.amplitude[r]), _step_at(fa.onset)) for fa in biases]
        out.append(_expr(BinOp("+", e.node, balanced("+", steps))))
    return tuple(out)


# --------------------------------------------------------------------------- generic slots
@dataclass(frozen=True)
class Slot:
    """The numbers of one slot of the generic fault form (``options.fault_slots``).

    Every fault type is one choice of these numbers; an unused slot is :meth:`empty`
    (no loss, no bias), so it leaves g_i and f_i unchanged.

    Attributes
    ----------
    onset : float
        Time the slot starts acting.
    severity : float
        Fraction of effectiveness lost while it acts (0 for a bias).
    duration : float
        Length of the ramp to full activity; 0 = abrupt.
    period, duty : float
        On/off period and the fraction of it on; ``period = 0`` = not intermittent.
    amplitude : tuple of float
        Bias added to f_i while it acts; ``()`` = no bias (zeros).
    """

    onset: float = 0.0
    severity: float = 0.0
    duration: float = 0.0
    period: float = 0.0
    duty: float = 0.0
    amplitude: tuple[float, ...] = ()

    @classmethod
    def of(cls, fault: Fault) -> Slot:
        """The slot numbers that reproduce ``fault``.

        Parameters
        ----------
        fault : Fault
            Any fault type.
        """
        if fault.is_bias:
            return cls(onset=fault.onset, amplitude=fault.amplitude)
        return cls(
            onset=fault.onset,
            severity=fault.severity,
            duration=fault.duration if fault.type == "ramp" else 0.0,
            period=fault.period if fault.type == "intermittent" else 0.0,
            duty=fault.duty if fault.type == "intermittent" else 0.0,
        )

    def bias(self, r: int) -> float:
        """Component ``r`` of the bias amplitude (0 when the slot has no bias).

        Parameters
        ----------
        r : int
            0-based coordinate.
        """
        return self.amplitude[r] if self.amplitude else 0.0


def slots_of(faults: tuple[Fault, ...], count: int) -> tuple[Slot, ...]:
    """``faults`` in file order in ``count`` slots, the rest padded with empty slots.

    Parameters
    ----------
    faults : tuple of Fault
        One follower's faults (the loader refuses more than ``count``).
    count : int
        ``options.fault_slots``.
    """
    if len(faults) > count:
        raise ValueError(f"{len(faults)} faults do not fit in {count} slots")
    return tuple(Slot.of(fa) for fa in faults) + (Slot(),) * (count - len(faults))


def slot_activation(slot: Slot) -> Node:
    """The node of act(t) in [0, 1]: how much of the slot acts at time t.

    act(t) = step(x) · min(1, x₊/(|D| + z_D) + z_D) · (1 − step(mod(x₊, |P| + z_P) − (c P + z_P)))

    with x = t − onset, x₊ = max(x, 0), D the duration, P the period, c the duty and
    z_D = step(−|D|), z_P = step(−|P|) (1 when D = 0, resp. P = 0, else 0). So act is 0
    before the onset and right-continuous: already 1 at the onset when D = 0, linear
    over [onset, onset + D] otherwise; with P > 0 it is on while mod(x, P) < c P
    (C fmod). Whatever the numbers, no denominator or modulus is 0 (|D| + z_D > 0,
    |P| + z_P > 0) and no ±inf meets a 0 (x₊ ≥ 0, ``max``/``min`` bound a quotient
    that overflows), so neither backend produces a NaN (CasADi's if_else evaluates
    both branches). x₊ in the modulus keeps the gate constant before the onset, so
    the breakpoint scan of :meth:`Expr.breakpoints` finds no time where nothing happens.

    Parameters
    ----------
    slot : Slot
    """
    x = BinOp("-", Time(), Num(slot.onset))
    x_pos = Call("max", (x, Num(0.0)))
    dur = Call("abs", (Num(slot.duration),))
    dur_zero = Call("step", (Neg(dur),))
    rise = BinOp("+", BinOp("/", x_pos, BinOp("+", dur, dur_zero)), dur_zero)
    ramp = BinOp("*", Call("step", (x,)), Call("min", (Num(1.0), rise)))
    per = Call("abs", (Num(slot.period),))
    per_zero = Call("step", (Neg(per),))
    phase = Call("mod", (x_pos, BinOp("+", per, per_zero)))
    on_len = BinOp("+", BinOp("*", Num(slot.duty), Num(slot.period)), per_zero)
    gate = BinOp("-", Num(1.0), Call("step", (BinOp("-", phase, on_len),)))
    return BinOp("*", ramp, gate)


def slotted_health(base: Expr, faults: tuple[Fault, ...], count: int) -> Expr:
    """g(t) = g_base(t) · Π_k (1 − severity_k act_k(t)) over ``count`` slots.

    Parameters
    ----------
    base : Expr
        The follower's own ``g``.
    faults : tuple of Fault
        The follower's faults (bias faults fill a slot with severity 0).
    count : int
        ``options.fault_slots``; 0 leaves ``base`` as it is.
    """
    slots = slots_of(faults, count)
    if not slots:
        return base
    factors = [
        BinOp("-", Num(1.0), BinOp("*", Num(sl.severity), slot_activation(sl))) for sl in slots
    ]
    return _expr(BinOp("*", base.node, balanced("*", factors)))


def slotted_bias(base: tuple[Expr, ...], faults: tuple[Fault, ...], count: int) -> tuple[Expr, ...]:
    """f_r(t) = f_base,r(t) + Σ_k amplitude_k,r act_k(t) over ``count`` slots.

    Parameters
    ----------
    base : tuple of Expr
        The follower's own ``f``, one per component.
    faults : tuple of Fault
        The follower's faults (loss-of-effectiveness faults fill a slot with amplitude 0).
    count : int
        ``options.fault_slots``; 0 leaves ``base`` as it is.
    """
    slots = slots_of(faults, count)
    if not slots:
        return base
    acts = [slot_activation(sl) for sl in slots]
    out = []
    for r, e in enumerate(base):
        terms = [BinOp("*", Num(sl.bias(r)), act) for sl, act in zip(slots, acts, strict=True)]
        out.append(_expr(BinOp("+", e.node, balanced("+", terms))))
    return tuple(out)


#: how far (in units of the last place) the generic form's switch may lie from the
#: nominal time onset + k period (+ duty period): rounding of t − onset, a few units
SWITCH_ULPS = 64


def fault_times(
    faults: tuple[Fault, ...], horizon: float, slots: int | None = None
) -> tuple[float, ...]:
    """The times where ``faults`` switch or kink, as the built g_i and f_i do.

    Without slots these are :meth:`Fault.times`. With slots, an intermittent fault
    switches where mod(t − onset, period) crosses 0 and duty·period; rounding of
    t − onset puts that a few units in the last place away from the nominal
    onset + k period (+ duty period), so each nominal time is replaced by the float
    at which the generic form really switches (found by evaluating it on the floats
    around the nominal time). The integrator then restarts exactly where the
    right-continuous fault takes its new value.

    Parameters
    ----------
    faults : tuple of Fault
        One follower's faults.
    horizon : float
        End of the run.
    slots : int or None
        ``options.fault_slots``.
    """
    out: list[float] = []
    for fa in faults:
        if slots is None or fa.type != "intermittent":
            out.extend(fa.times(horizon))
        else:
            out.extend(_generic_switches(fa, horizon))
    return tuple(out)


def _generic_switches(fault: Fault, horizon: float) -> tuple[float, ...]:
    """The on/off floats of an intermittent fault in the generic form (see :func:`fault_times`)."""
    nominal = np.array(fault.times(horizon), dtype=float)
    if nominal.size == 0:
        return ()
    new = np.tile([1.0, 0.0], nominal.size // 2)  # on, off, on, off, ...
    offsets = np.arange(-SWITCH_ULPS, SWITCH_ULPS + 1, dtype=np.int64)
    bits = np.maximum(nominal.view(np.int64)[:, None] + offsets, 0)  # floats >= 0 are ordered
    grid = bits.view(np.float64)
    act = Expr("act", slot_activation(Slot.of(fault))).numpy(grid)
    is_new = np.broadcast_to(act, grid.shape) == new[:, None]
    flips = is_new[:, 1:] & ~is_new[:, :-1]  # flips[i, j]: the switch is at grid[i, j + 1]
    out = nominal.copy()
    for i in np.flatnonzero(flips.any(axis=1)):
        j = np.flatnonzero(flips[i]) + 1
        out[i] = grid[i, j[np.argmin(np.abs(j - SWITCH_ULPS))]]
    return tuple(float(x) for x in out)


def balanced(op: str, terms: list[Node]) -> Node:
    """``terms`` joined by ``op`` (``"+"`` or ``"*"``) as a balanced tree (shallow for long lists).

    Parameters
    ----------
    op : str
        An associative operator.
    terms : list of Node
        Expression nodes, at least one.
    """
    if len(terms) == 1:
        return terms[0]
    mid = len(terms) // 2
    return BinOp(op, balanced(op, terms[:mid]), balanced(op, terms[mid:]))


def node_text(node: Node) -> str:
    """The node as fully parenthesised text that parses back to the same function.

    The text names the expression (the closed loop shares evaluations of equal texts).

    Parameters
    ----------
    node : Node
        An :class:`~core.expressions.Expr` node.
    """
    return visit(node, _TEXT)


class _Text(Visitor[str]):
    """:func:`node_text`: negative numbers in parentheses, spaces around operators."""

    def num(self, node: Num) -> str:
        return repr(node.value) if node.value >= 0 else f"({node.value!r})"

    def time(self, node: Time) -> str:
        return "t"

    def neg(self, node: Neg) -> str:
        return f"(-{visit(node.arg, self)})"

    def binop(self, node: BinOp) -> str:
        return f"({visit(node.left, self)} {node.op} {visit(node.right, self)})"

    def call(self, node: Call) -> str:
        return f"{node.name}({', '.join(visit(a, self) for a in node.args)})"


_TEXT = _Text()


def _expr(node: Node) -> Expr:
    return Expr(node_text(node), node)


def _step_at(t0: float) -> Node:
    """``step(t - t0)``: 0 before ``t0``, 1 from ``t0`` on."""
    return Call("step", (BinOp("-", Time(), Num(t0)),))
