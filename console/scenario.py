"""The console's scenario: a scenario file with every number the operator sets made plain.

From the file the console is started on, :func:`console_table` keeps everything but:

* ``leader.u0 = ["0.0 + 0.0*smoothstep((t - 0.0)/1.0) + ...", ...]``: per input a number a
  and :data:`console.ramps.RAMP_SLOTS` shaped changes d_j·smoothstep((t − c_j)/r_j), whose
  literals are runtime parameters (``expr:leader.u0[k]``) the console sets: a the command
  with every finished ramp, (d_j, c_j, r_j) a change of size d_j landing at time c_j and
  rising over r_j seconds (a trace ``u0_csv``, ``u0_rise`` and ``u0_shape`` are dropped:
  the console shapes the operator's changes itself);
* each follower's ``g`` is its value at t = 0 in the same form (``expr:followers[i].g``);
* each follower's ``f_r`` becomes ``(f_r) + a + d*step(t - c)``, a the bias the operator
  adds (``expr:followers[i].f[r]``, last three literals);
* each follower's ``d`` is the bound of the original f (given, or its sup) plus
  ``bias_max``, so Assumption 3 holds for every bias the console accepts and the
  controller's d_i does not change when a bias is set;
* the file's own faults and graph switches are removed (the console starts healthy;
  the operator injects faults live); :data:`LINK_SLOTS` switches that change nothing are
  added, so that the page's outputs (the symbolic closed loop's) read the graphs the
  engine integrates, the link changes a fade still runs (``graph``, ``graph_times``:
  :func:`symbolic.closed_loop.graph_coupling`);
* ``integration.method`` is ``native``: the console runs the per-agent engine
  (:class:`console.engine.LiveLoop`), and so does the replay of its records;
* ``name`` gets the suffix ``-console``.

The replay of a record (:mod:`console.record`) is this table plus the recorded changes.
"""

from __future__ import annotations

import copy
import hashlib
import tomllib
from pathlib import Path

import numpy as np

from console.ramps import RAMP_SLOTS
from core.errors import ScenarioError
from core.scenario import Scenario, load_scenario, scenario_from_dict
from sweep.sampler import scenario_toml

#: default bound on each bias component the operator may add to f_i
BIAS_MAX = 5.0
#: a number the console sets, a, switching to a + d at time c (literals a, d, c)
SWITCHED = "{!r} + 0.0*step(t - 0.0)"
#: link changes a fade may still run at once (the page's outputs read 1 + LINK_SLOTS graphs;
#: a change beyond is refused until the oldest fade ends: console/engine.py)
LINK_SLOTS = 8
#: the operator's command: a number a and RAMP_SLOTS ramps d*smoothstep((t - c)/r)
RAMPED = "0.0" + " + 0.0*smoothstep((t - 0.0)/1.0)" * RAMP_SLOTS


def console_table(path: str | Path, bias_max: float = BIAS_MAX) -> dict:
    """The console scenario of the file at ``path``, as a TOML table.

    Parameters
    ----------
    path : str or Path
        A scenario file (validated completely first).
    bias_max : float
        Largest bias component the operator may add (> 0).

    Raises
    ------
    ScenarioError
        If the file is not a valid scenario, or ``bias_max`` is not positive.
    """
    path = Path(path)
    if not bias_max > 0:
        raise ScenarioError(str(path), "--bias-max", f"{bias_max:g}", "a number > 0")
    base = load_scenario(path)
    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    data = copy.deepcopy(raw)
    data["name"] = f"{base.name}-console"
    leader = data["leader"]
    for k in ("u0_csv", "u0_hold", "u0_rise", "u0_shape"):
        leader.pop(k, None)
    leader["u0"] = [RAMPED] * base.p
    # the console runs the per-agent engine (console/engine.py): its replay runs it too
    data.setdefault("integration", {})["method"] = "native"
    graph = data["graph"]
    graph.pop("switches", None)
    # graph.link_fade stays the file's (default: the fade): LiveLoop carries every link
    # change whose fade still runs into the next call (engine.py, LiveLoop.topologies)
    # LINK_SLOTS switches that change nothing: the page's outputs (the symbolic whole loop)
    # then read up to 1 + LINK_SLOTS topologies, the link changes a fade still runs
    i = int(np.flatnonzero(base.graph.pinning)[0])
    T = base.integration.horizon
    graph["switches"] = [
        {
            "time": T / 2 + k * T / (4 * LINK_SLOTS),  # distinct times: one topology each
            "follower": i + 1,
            "neighbour": 0,
            "weight": float(base.graph.pinning[i]),
        }
        for k in range(LINK_SLOTS)
    ]
    for fo, tbl in zip(base.followers, data["followers"], strict=True):
        tbl.pop("faults", None)
        tbl["g"] = SWITCHED.format(float(fo.g.expr.numpy(0.0)))
        tbl["f"] = [f"({e.text}) + " + SWITCHED.format(0.0) for e in fo.f]
        tbl.pop("d", None)
    # d as the file gives it, or as the loader derives it from f without the file's faults
    plain = scenario_from_dict(copy.deepcopy(data), path=path, sha256=_sha(data))
    for i, tbl in enumerate(data["followers"]):
        given = "d" in raw["followers"][i]
        d = base.followers[i].d if given else plain.followers[i].d
        tbl["d"] = (np.asarray(d, dtype=float) + bias_max).tolist()
    return data


def _sha(data: dict) -> str:
    return hashlib.sha256(scenario_toml(data).encode("utf-8")).hexdigest()


def console_scenario(path: str | Path, table: dict) -> Scenario:
    """``table`` validated like a file (relative paths resolved against ``path``).

    Parameters
    ----------
    path : str or Path
        The file the table came from.
    table : dict
        :func:`console_table`'s result.
    """
    return scenario_from_dict(copy.deepcopy(table), path=Path(path), sha256=_sha(table))
