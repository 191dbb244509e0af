"""Reproducible samples of a study, each turned into a validated scenario.

Sample k draws from ``numpy.random.default_rng(seed_k)`` where ``seed_k`` comes from
``SeedSequence([study.seed, k])``: sample k is the same whichever other samples are
drawn, and in whatever order (a study can be resumed or split).
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import atomic_write_text
from core.errors import ExpressionError, ScenarioError
from core.faults import FAULT_TYPES
from core.graph import unreachable_followers
from core.overrides import set_path
from core.scenario import Scenario, scenario_from_dict
from sweep.distributions import Distribution
from sweep.families import FaultFamily, LinkLosses, substitute
from sweep.graphs import random_graph, resize_followers
from sweep.study import Study


@dataclass(frozen=True)
class Sample:
    """One sample of a study.

    Attributes
    ----------
    id : int
        0-based sample number.
    seed : int
        Seed of the sample's generator (``numpy.random.default_rng(seed)``).
    params : dict
        What was drawn: ``--set`` keys, ``graph.N``, ``operator.<name>`` or
        ``operator.trace`` -> value.
    scenario_data : dict
        The full scenario table (what :func:`scenario_toml` writes).
    scenario : Scenario or None
        The validated scenario, or None when the loader refused the sample.
    reason : str or None
        The loader's one-line refusal, or None.
    """

    id: int
    seed: int
    params: dict[str, Any]
    scenario_data: dict
    scenario: Scenario | None
    reason: str | None


def sample_seed(study_seed: int, sample_id: int) -> int:
    """The seed of sample ``sample_id``: from ``SeedSequence([study_seed, sample_id])``.

    Parameters
    ----------
    study_seed : int
        The study's seed.
    sample_id : int
        The sample's id.
    """
    state = np.random.SeedSequence([study_seed, sample_id]).generate_state(2, np.uint32)
    return int(state[0]) << 32 | int(state[1])


def draw(d: Distribution, rng: np.random.Generator) -> Any:
    """One value of ``d`` (a list of ``d.size`` values when sized).

    Parameters
    ----------
    d : Distribution
        The distribution.
    rng : numpy.random.Generator
        Source of randomness.
    """
    n = 1 if d.size is None else d.size
    if d.kind == "uniform":
        vals = rng.uniform(d.args[0], d.args[1], n).tolist()
    elif d.kind == "integers":
        vals = rng.integers(d.args[0], d.args[1], n, endpoint=True).tolist()
    elif d.kind == "choice":
        vals = [copy.deepcopy(d.args[i]) for i in rng.integers(len(d.args), size=n)]
    elif d.truncate is None:
        vals = rng.normal(d.args[0], d.args[1], n).tolist()
    else:
        from scipy.stats import truncnorm  # 1 s to import: only for truncated normals

        mean, std = d.args
        a, b = ((x - mean) / std for x in d.truncate)
        vals = truncnorm.rvs(a, b, loc=mean, scale=std, size=n, random_state=rng).tolist()
    return vals[0] if d.size is None else vals


def samples(study: Study, ids: Iterable[int] | None = None) -> Iterator[Sample]:
    """The study's samples (all, or those in ``ids``), each validated by the loader.

    Parameters
    ----------
    study : Study
        From :func:`sweep.study.load_study`.
    ids : iterable of int, optional
        Which samples (default ``range(study.count)``); sample k is the same in any subset.

    Yields
    ------
    Sample
        A sample the loader refuses carries its ``reason`` instead of raising.
    """
    for k in range(study.count) if ids is None else ids:
        if not 0 <= k < study.count:
            raise ValueError(f"sample id {k} outside 0..{study.count - 1}")
        yield make_sample(study, k)


def make_sample(study: Study, sample_id: int) -> Sample:
    """Draw sample ``sample_id`` and validate it.

    Parameters
    ----------
    study : Study
        The study.
    sample_id : int
        0-based id.
    """
    seed = sample_seed(study.seed, sample_id)
    rng = np.random.default_rng(seed)
    data = copy.deepcopy(study.base_data)
    data["name"] = sample_name(study, sample_id)
    data["description"] = f"sample {sample_id} of study {study.name} (seed {seed})"
    params: dict[str, Any] = {}
    try:
        _draw_graph(study, data, params, rng)
        for key, v in study.fixed_for(len(data["followers"])).items():
            set_path(data, f"{study.path}#{sample_id}", key, copy.deepcopy(v))
        _draw_operator(study, data, params, rng)
        _draw_faults(study.faults, data, params, rng)
        for key, d in study.params.items():
            params[key] = draw(d, rng)
            set_path(data, f"{study.path}#{sample_id}", key, params[key])
        sc = scenario_from_dict(
            data, path=f"{study.path}#{sample_id}", sha256=_sha(scenario_toml(data))
        )
    except (ScenarioError, ExpressionError) as exc:
        return Sample(sample_id, seed, params, data, None, str(exc))
    return Sample(sample_id, seed, params, data, sc, None)


def sample_name(study: Study, sample_id: int) -> str:
    """``<study name>-<id, 4 digits>``, the sample scenario's name.

    Parameters
    ----------
    study : Study
        The study.
    sample_id : int
        0-based id.
    """
    return f"{study.name}-{sample_id:04d}"


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _draw_graph(study: Study, data: dict, params: dict, rng: np.random.Generator) -> None:
    """Replace [graph] by a random graph and make [[followers]] N long."""
    g = study.graph
    if g is None:
        return
    N = int(rng.integers(g.n_range[0], g.n_range[1], endpoint=True))
    A, b = random_graph(N, g.edge_probability, g.weight, rng)
    data["graph"] = {"adjacency": A.tolist(), "pinning": b.tolist()}
    resize_followers(data, N)
    params["graph.N"] = N
    params["graph.edges"] = int(np.count_nonzero(A) + np.count_nonzero(b))
    if g.losses is not None:
        _draw_losses(g.losses, data, params, rng)


def _draw_losses(losses: LinkLosses, data: dict, params: dict, rng: np.random.Generator) -> None:
    """Lose distinct links of the drawn graph ([[graph.switches]] with weight 0), each
    perhaps restored to its weight ``recovery`` seconds later (dropped past the horizon)."""
    A = np.asarray(data["graph"]["adjacency"], float)
    b = np.asarray(data["graph"]["pinning"], float)
    # plain Python numbers: the weights are written into the scenario table
    links = [(int(i), int(j) + 1, float(A[i, j])) for i, j in zip(*np.nonzero(A), strict=True)]
    if losses.pinning:
        links += [(int(i), 0, float(b[i])) for i in np.flatnonzero(b)]
    n = int(rng.integers(losses.count[0], losses.count[1], endpoint=True))
    horizon = data.get("integration", {}).get("horizon", math.inf)
    if losses.reachable:  # every link a candidate in a drawn order, kept if A1 holds
        candidates = rng.permutation(len(links))
    else:
        candidates = rng.choice(len(links), size=min(n, len(links)), replace=False)
    switches: list[dict] = []
    k = 0  # links lost so far
    for c in candidates:
        if k == n:
            break
        i, j, w = links[c]
        t = draw(losses.time, rng)
        key = f"graph.loss[{k + 1}]"
        drawn = {f"{key}.follower": i + 1, f"{key}.neighbour": j, f"{key}.time": t}
        new = [{"time": t, "follower": i + 1, "neighbour": j, "weight": 0.0}]
        if losses.recovery is not None:
            back = t + draw(losses.recovery, rng)
            drawn[f"{key}.recovery"] = back
            if back < horizon:
                new.append({"time": back, "follower": i + 1, "neighbour": j, "weight": w})
        if losses.reachable and not keeps_reachable(A, b, switches + new):
            continue
        params.update(drawn)
        switches += new
        k += 1
    if switches:
        data["graph"]["switches"] = sorted(switches, key=lambda s: s["time"])


def keeps_reachable(A: np.ndarray, b: np.ndarray, switches: list[dict]) -> bool:
    """Whether every topology that ``switches`` make of (A, b) keeps every follower
    reachable from the leader (Assumption 1; :func:`core.graph.unreachable_followers`).

    Parameters
    ----------
    A, b : ndarray
        The drawn graph's adjacency and pinning.
    switches : list of dict
        ``[[graph.switches]]`` entries (time, follower, neighbour (0 = the leader), weight).
    """
    A, b = A.copy(), b.copy()
    for s in sorted(switches, key=lambda s: s["time"]):
        i, j = s["follower"] - 1, s["neighbour"]
        if j == 0:
            b[i] = s["weight"]
        else:
            A[i, j - 1] = s["weight"]
        if unreachable_followers(A, b):
            return False
    return True


def _draw_faults(
    fam: FaultFamily | None, data: dict, params: dict, rng: np.random.Generator
) -> None:
    """Add the drawn faults to the followers' ``faults`` lists (after the base's own):
    per fault the follower, the type, then the type's keys in the order it lists them."""
    if fam is None:
        return
    n = int(rng.integers(fam.count[0], fam.count[1], endpoint=True))
    pool = fam.followers or tuple(range(1, len(data["followers"]) + 1))
    params["faults.count"] = n
    for k in range(1, n + 1):
        who = pool[int(rng.integers(len(pool)))]
        kind = fam.types[int(rng.integers(len(fam.types)))]
        fault = {"type": kind, **{key: draw(fam.keys[key], rng) for key in FAULT_TYPES[kind][1:]}}
        follower = data["followers"][who - 1]
        follower["faults"] = [*follower.get("faults", []), fault]
        params.update({f"faults[{k}].follower": who, f"faults[{k}].type": kind})
        params.update({f"faults[{k}].{key}": v for key, v in fault.items() if key != "type"})


def _draw_operator(study: Study, data: dict, params: dict, rng: np.random.Generator) -> None:
    """Set leader.u0 from the family, or leader.u0_csv to a chosen trace."""
    op = study.operator
    if op is None:
        return
    leader = data["leader"]
    leader.pop("u0", None)
    leader.pop("u0_csv", None)
    if op.traces:
        trace = op.traces[int(rng.integers(len(op.traces)))]
        leader["u0_csv"] = params["operator.trace"] = trace
        return
    values = {name: draw(d, rng) for name, d in op.params.items()}
    params.update({f"operator.{name}": v for name, v in values.items()})
    leader["u0"] = [substitute(e, values) for e in op.u0]


# --------------------------------------------------------------------------- TOML writer
def scenario_toml(data: dict) -> str:
    """A scenario table as TOML text that :func:`tomllib.loads` reads back equal.

    Top-level values first, then one ``[table]`` per table and one ``[[name]]`` per entry
    of an array of tables; deeper tables are written inline.

    Parameters
    ----------
    data : dict
        Strings, booleans, integers, finite floats, lists and tables.
    """
    head, body = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            body += ["", f"[{_key(k)}]", *_assignments(v)]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                body += ["", f"[[{_key(k)}]]", *_assignments(x)]
        else:
            head.append(f"{_key(k)} = {_value(v)}")
    return "\n".join(head + body) + "\n"


def _assignments(table: dict) -> list[str]:
    return [f"{_key(k)} = {_value(v)}" for k, v in table.items()]


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, np.generic):  # a numpy scalar's repr is not TOML (np.float64(1.0))
        v = v.item()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def write_scenario(sample: Sample, folder: str | Path) -> Path:
    """Write the sample's scenario file ``<folder>/<name>.toml`` (atomically).

    Parameters
    ----------
    sample : Sample
        A drawn sample.
    folder : str or Path
        Created if missing.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(folder) / f"{sample.scenario_data['name']}.toml"
    return atomic_write_text(path, scenario_toml(sample.scenario_data))
