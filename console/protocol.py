"""The messages a console page may send, validated before anything acts on them.

Every message is one JSON object with a ``type``. :func:`parse_message` turns the
raw text into a :class:`Command` or raises :class:`MessageError`, whose one-line
text goes back to the page as ``{"type": "error", "message": ...}``; the loop never
sees an invalid command. Followers are 1-based in messages (``followers[1]``), as in
files and messages everywhere in the toolkit; neighbour 0 is the leader.

==========  ==============================================  ==========================
type        fields                                          effect
==========  ==============================================  ==========================
``u0``      ``value``: p numbers, each ``|u0_k| <= u_max``   operator command, held
``pause``   —                                               stop the simulated clock
``resume``  —                                               start it again
``reset``   —                                               back to t = 0, new record
``scale``   ``value``: simulated seconds per real second    time scale
``health``  ``follower``, ``value`` in [g_min, 1]           set g_i
``bias``    ``follower``, ``value``: n numbers              set the added f_i bias
``link``    ``follower``, ``neighbour``, ``cut``: bool      cut or restore an edge
``clear``   ``follower``                                    remove that follower's faults
``drive``   —                                               ask to be the driving page
``save``    —                                               write the record so far
==========  ==============================================  ==========================
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from core.errors import ToolkitError

#: longest message accepted (a u0 message is ~40 bytes)
MAX_MESSAGE_BYTES = 4096
#: time scale bounds: simulated seconds per wall-clock second
SCALE_RANGE = (0.05, 20.0)
#: the scales the page's + and − step through (1 among them, the ends the bounds)
SCALES = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
#: commands only the driving page may send (the others watch)
DRIVER_ONLY = frozenset({"u0", "pause", "resume", "reset", "scale", "health", "bias", "link"})
DRIVER_ONLY |= {"clear", "save"}
KNOWN = DRIVER_ONLY | {"drive"}


class MessageError(ToolkitError):
    """A page's message was refused; the text says which field and what is expected."""


@dataclass(frozen=True)
class Limits:
    """What a message may ask for, from the console scenario.

    Attributes
    ----------
    N : int
        Followers (messages name 1..N).
    n : int
        Coordinates per follower (length of a bias).
    p : int
        Operator inputs (length of u0).
    u_max : float
        Bound on each |u0_k|: α/√p, so that ‖u0‖ ≤ α (the bound the followers design for).
    g_min : float
        Smallest health (``controller.g_min``; the scenario's rules need g_i ≥ g_min).
    bias_max : float
        Bound on each bias component (the followers' ``d`` includes it).
    edges : frozenset of (int, int)
        The graph's edges as (follower, neighbour), 1-based, neighbour 0 = the leader.
    """

    N: int
    n: int
    p: int
    u_max: float
    g_min: float
    bias_max: float
    edges: frozenset[tuple[int, int]] = field(default_factory=frozenset)


@dataclass(frozen=True)
class Command:
    """One validated message.

    Attributes
    ----------
    kind : str
        The message ``type``.
    follower : int or None
        0-based follower index (messages are 1-based).
    neighbour : int or None
        0-based neighbour follower index, or -1 for the leader (pinning).
    values : tuple of float
        ``u0``, ``bias``: the vector; ``health``, ``scale``: one number.
    cut : bool
        ``link``: True to cut, False to restore.
    """

    kind: str
    follower: int | None = None
    neighbour: int | None = None
    values: tuple[float, ...] = ()
    cut: bool = False


#: the fields each message type may have (any other is refused, named)
FIELDS = {
    "u0": ("value",),
    "scale": ("value",),
    "health": ("follower", "value"),
    "bias": ("follower", "value"),
    "link": ("follower", "neighbour", "cut"),
    "clear": ("follower",),
}


class _Constant:
    """JSON's NaN/Infinity/-Infinity, kept as a marker so the field that holds one is named."""

    def __init__(self, name: str) -> None:
        self.name = name


def parse_message(text: str | bytes, limits: Limits) -> Command:
    """Validate one raw message.

    Parameters
    ----------
    text : str or bytes
        What the page sent.
    limits : Limits
        Ranges and names the message is checked against.

    Returns
    -------
    Command

    Raises
    ------
    MessageError
        One line naming the field and what is expected.
    """
    if len(text) > MAX_MESSAGE_BYTES:
        raise MessageError(f"message: {len(text)} bytes (expected at most {MAX_MESSAGE_BYTES})")
    try:
        msg = json.loads(text, parse_constant=_Constant)
    except (ValueError, RecursionError) as exc:
        raise MessageError(f"message: not JSON ({_brief(exc)}) (expected a JSON object)") from None
    if not isinstance(msg, dict):
        raise MessageError('message: not a JSON object (expected {"type": ...})')
    kind = msg.get("type")
    if not isinstance(kind, str) or kind not in KNOWN:
        raise MessageError(
            f"type: {_show(kind)} is unknown (expected one of {', '.join(sorted(KNOWN))})"
        )
    allowed = FIELDS.get(kind, ())
    unknown = sorted(k for k in msg if k != "type" and k not in allowed)
    if unknown:
        names = ", ".join(_show(k) for k in unknown)
        want = ", ".join(allowed) if allowed else "no field besides type"
        raise MessageError(
            f"{names}: unknown field{'s' if len(unknown) > 1 else ''} of a {kind!r} message "
            f"(expected {want})"
        )
    return _PARSERS.get(kind, _bare)(kind, msg, limits)


def _num(x: float) -> str:
    """A number with every digit it needs to be told apart (shortest round trip), no '.0'."""
    r = repr(float(x))
    return r[:-2] if r.endswith(".0") else r


def _brief(exc: Exception) -> str:
    return str(exc).split(":")[0][:80]


def _show(v: Any) -> str:
    if isinstance(v, _Constant):
        return v.name
    try:
        s = json.dumps(v, default=lambda c: c.name) if not isinstance(v, str) else repr(v)
    except ValueError:  # an integer too long for json.dumps' digit limit
        s = "a number too large"
    return s if len(s) <= 40 else s[:37] + "..."


def _number(v: Any, field_: str, lo: float, hi: float) -> float:
    """A finite JSON number in [lo, hi] (booleans are not numbers)."""
    bounds = f"[{_num(lo)}, {_num(hi)}]"
    if isinstance(v, _Constant):
        raise MessageError(f"{field_}: {v.name} is not a finite number (expected one in {bounds})")
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise MessageError(f"{field_}: {_show(v)} is not a number (expected a number in {bounds})")
    try:
        x = float(v)
    except OverflowError:  # an integer of hundreds of digits
        digits = len(str(abs(v)))
        raise MessageError(
            f"{field_}: a {digits}-digit number is out of range {bounds} (expected a number in it)"
        ) from None
    if not math.isfinite(x):
        raise MessageError(f"{field_}: {x!r} is not a finite number (expected one in {bounds})")
    if not lo <= x <= hi:
        raise MessageError(
            f"{field_}: {_num(x)} is out of range {bounds} (expected a number in it)"
        )
    return x


def _vector(v: Any, field_: str, size: int, bound: float) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != size:
        raise MessageError(f"{field_}: {_show(v)} (expected a list of {size} numbers)")
    return tuple(_number(x, f"{field_}[{k}]", -bound, bound) for k, x in enumerate(v))


def _follower(msg: dict, limits: Limits, key: str = "follower") -> int:
    v = msg.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= limits.N:
        raise MessageError(f"{key}: {_show(v)} is not a follower (expected 1..{limits.N})")
    return v - 1


def _bare(kind: str, msg: dict, limits: Limits) -> Command:
    return Command(kind)


def _u0(kind: str, msg: dict, limits: Limits) -> Command:
    return Command(kind, values=_vector(msg.get("value"), "value", limits.p, limits.u_max))


def _scale(kind: str, msg: dict, limits: Limits) -> Command:
    return Command(kind, values=(_number(msg.get("value"), "value", *SCALE_RANGE),))


def _health(kind: str, msg: dict, limits: Limits) -> Command:
    g = _number(msg.get("value"), "value", limits.g_min, 1.0)
    if g <= 0.0:
        raise MessageError("value: 0 is not a health (expected 0 < g <= 1)")
    return Command(kind, follower=_follower(msg, limits), values=(g,))


def _bias(kind: str, msg: dict, limits: Limits) -> Command:
    i = _follower(msg, limits)
    return Command(
        kind, follower=i, values=_vector(msg.get("value"), "value", limits.n, limits.bias_max)
    )


def _link(kind: str, msg: dict, limits: Limits) -> Command:
    i = _follower(msg, limits)
    j = msg.get("neighbour")
    if isinstance(j, bool) or not isinstance(j, int) or (i + 1, j) not in limits.edges:
        heard = sorted(jj for ii, jj in limits.edges if ii == i + 1)
        names = ", ".join("0 (leader)" if jj == 0 else str(jj) for jj in heard) or "none"
        raise MessageError(
            f"neighbour: {_show(j)} is not heard by follower {i + 1} (expected one of: {names})"
        )
    cut = msg.get("cut")
    if not isinstance(cut, bool):
        raise MessageError(
            f"cut: {_show(cut)} (expected true to cut the link, false to restore it)"
        )
    return Command(kind, follower=i, neighbour=j - 1, cut=cut)


def _clear(kind: str, msg: dict, limits: Limits) -> Command:
    return Command(kind, follower=_follower(msg, limits))


_PARSERS = {
    "u0": _u0,
    "scale": _scale,
    "health": _health,
    "bias": _bias,
    "link": _link,
    "clear": _clear,
}
