"""A study's space as a unit box: each drawn number of a sample is one coordinate.

Coordinate u in [0, 1] is mapped through the inverse distribution function of its study
distribution (``uniform``: lo + u (hi - lo); ``normal``: its quantile, truncated when the
study truncates it; ``integers`` and ``choice``: equal-width cells), so a uniform point of
the box is a sample of the study's own distribution. A point's sample is built in the
order of :func:`sweep.sampler.make_sample`: ``[set]``, ``[operator]``, ``[faults]``,
``[params]``. A group (a ``[params]`` key, the operator, one fault) can be *dropped*:
it then keeps the base scenario's value (the base's u0; no fault), which is how the
minimised reproduction moves a run back toward its base.
"""

from __future__ import annotations

import copy
import hashlib
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.errors import ExpressionError, ScenarioError
from core.faults import FAULT_TYPES
from core.overrides import set_path
from core.scenario import scenario_from_dict
from sweep.sampler import Sample, scenario_toml
from sweep.study import Distribution, Study, substitute


@dataclass(frozen=True)
class Dimension:
    """One coordinate of the box.

    Attributes
    ----------
    name : str
        The value's key (``followers[1].p0[2]``, ``operator.A1``, ``faults[1].severity``).
    group : str
        What dropping reverts (``[params]`` key, ``operator``, ``faults[k]``).
    dist : Distribution
        The study's distribution of this one value (unsized).
    neutral : float or None
        The value toward which minimisation bisects (the base's value; 0 for operator
        parameters and bias amplitudes when 0 is in range), None for categorical ones.
    """

    name: str
    group: str
    dist: Distribution
    neutral: float | None


def dimensions(study: Study) -> tuple[Dimension, ...]:
    """The box's coordinates for ``study``, in sampling order.

    Parameters
    ----------
    study : Study
        A study without ``[graph]`` and without operator traces.
    """
    dims: list[Dimension] = []
    op = study.operator
    if op is not None:
        for name, d in op.params.items():
            dims += _scalar_dims(f"operator.{name}", "operator", d, 0.0)
    fam = study.faults
    if fam is not None:
        if fam.count[0] != fam.count[1]:
            dims.append(
                Dimension("faults.count", "faults", Distribution("integers", fam.count), None)
            )
        pool = fam.followers or tuple(range(1, len(study.base_data["followers"]) + 1))
        for k in range(1, fam.count[1] + 1):
            g = f"faults[{k}]"
            dims.append(Dimension(f"{g}.follower", g, Distribution("choice", tuple(pool)), None))
            dims.append(Dimension(f"{g}.type", g, Distribution("choice", fam.types), None))
            for key, d in fam.keys.items():
                neutral = 0.0 if key in ("severity", "amplitude") else None
                dims += _scalar_dims(f"{g}.{key}", g, d, neutral)
    for key, d in study.params.items():
        base = _base_value(study.base_data, key)
        dims += _scalar_dims(key, key, d, base)
    return tuple(dims)


def _scalar_dims(name: str, group: str, d: Distribution, neutral: Any) -> list[Dimension]:
    one = Distribution(d.kind, d.args, None, d.truncate)
    if d.size is None:
        return [Dimension(name, group, one, _neutral(one, neutral))]
    vals = neutral if isinstance(neutral, list) else [neutral] * d.size
    return [
        Dimension(f"{name}[{k + 1}]", group, one, _neutral(one, vals[k] if k < len(vals) else None))
        for k in range(d.size)
    ]


def _neutral(d: Distribution, v: Any) -> float | None:
    """``v`` clipped to ``d``'s range when ``d`` is numeric and ``v`` a number."""
    if d.kind == "choice" or isinstance(v, bool) or not isinstance(v, int | float):
        return None
    lo, hi = _range(d)
    return float(min(max(v, lo), hi))


def _range(d: Distribution) -> tuple[float, float]:
    if d.kind in ("uniform", "integers"):
        return float(d.args[0]), float(d.args[1])
    if d.truncate is not None:
        return float(d.truncate[0]), float(d.truncate[1])
    return -math.inf, math.inf


def _base_value(data: dict, key: str) -> Any:
    """The base scenario's value at a ``--set`` key (1-based indices), or None."""
    node: Any = data
    for part in key.split("."):
        name, _, index = part.partition("[")
        node = node.get(name) if isinstance(node, dict) else None
        if index:
            i = int(index.rstrip("]"))
            node = node[i - 1] if isinstance(node, list) and 1 <= i <= len(node) else None
        if node is None:
            return None
    return node


def value(d: Distribution, u: float) -> Any:
    """The value of ``d`` at unit coordinate ``u`` (inverse distribution function).

    Parameters
    ----------
    d : Distribution
        Unsized.
    u : float
        In [0, 1] (clipped).
    """
    u = min(max(float(u), 0.0), 1.0)
    if d.kind == "uniform":
        return float(d.args[0] + u * (d.args[1] - d.args[0]))
    if d.kind == "integers":
        n = d.args[1] - d.args[0] + 1
        return int(d.args[0] + min(int(u * n), n - 1))
    if d.kind == "choice":
        return copy.deepcopy(d.args[min(int(u * len(d.args)), len(d.args) - 1)])
    from scipy.stats import norm, truncnorm

    mean, std = d.args
    u = min(max(u, 1e-6), 1 - 1e-6)
    if d.truncate is None:
        return float(norm.ppf(u, mean, std))
    a, b = ((x - mean) / std for x in d.truncate)
    return float(truncnorm.ppf(u, a, b, loc=mean, scale=std))


def values_at(dims: tuple[Dimension, ...], u: Iterable[float]) -> dict[str, Any]:
    """Each dimension's value at the point ``u`` of the box.

    Parameters
    ----------
    dims : tuple of Dimension
        From :func:`dimensions`.
    u : iterable of float
        One coordinate per dimension.
    """
    u = list(u)
    if len(u) != len(dims):
        raise ValueError(f"point has {len(u)} coordinates, the box {len(dims)}")
    return {d.name: value(d.dist, x) for d, x in zip(dims, u, strict=True)}


def build_sample(
    study: Study,
    values: dict[str, Any],
    name: str,
    dropped: frozenset[str] = frozenset(),
    sample_id: int = 0,
) -> Sample:
    """The scenario of a point: the base, ``[set]``, then the point's values.

    Parameters
    ----------
    study : Study
        The search's study.
    values : dict
        Dimension name -> value (:func:`values_at`).
    name : str
        The scenario's name.
    dropped : frozenset of str
        Groups that keep the base scenario's value.
    sample_id : int
        The sample's id in the result (the evaluation index).

    Returns
    -------
    Sample
        ``scenario`` None and ``reason`` set when the loader refuses it.
    """
    data = copy.deepcopy(study.base_data)
    data["name"] = name
    data["description"] = f"point {name} of search {study.name}"
    where = f"{study.path}#{name}"
    params: dict[str, Any] = {}
    try:
        for key, v in study.fixed.items():
            set_path(data, where, key, copy.deepcopy(v))
        _operator(study, values, data, params, dropped)
        _faults(study, values, data, params, dropped)
        for key, d in study.params.items():
            if key in dropped:
                continue
            v = (
                values[key]
                if d.size is None
                else [values[f"{key}[{k + 1}]"] for k in range(d.size)]
            )
            params[key] = v
            set_path(data, where, key, v)
        text = scenario_toml(data)
        sc = scenario_from_dict(data, path=where, sha256=hashlib.sha256(text.encode()).hexdigest())
    except (ScenarioError, ExpressionError) as exc:
        return Sample(sample_id, 0, params, data, None, str(exc))
    return Sample(sample_id, 0, params, data, sc, None)


def _operator(study: Study, values: dict, data: dict, params: dict, dropped: frozenset) -> None:
    op = study.operator
    if op is None or "operator" in dropped:
        return
    leader = data["leader"]
    leader.pop("u0", None)
    leader.pop("u0_csv", None)
    vals = {n: values[f"operator.{n}"] for n in op.params}
    params.update({f"operator.{n}": v for n, v in vals.items()})
    leader["u0"] = [substitute(e, vals) for e in op.u0]


def _faults(study: Study, values: dict, data: dict, params: dict, dropped: frozenset) -> None:
    fam = study.faults
    if fam is None or "faults" in dropped:
        return
    n = int(values.get("faults.count", fam.count[1]))
    for k in range(1, n + 1):
        g = f"faults[{k}]"
        if g in dropped:
            continue
        who, kind = values[f"{g}.follower"], values[f"{g}.type"]
        fault: dict[str, Any] = {"type": kind}
        for key in FAULT_TYPES[kind][1:]:
            d = fam.keys[key]
            fault[key] = (
                values[f"{g}.{key}"]
                if d.size is None
                else [values[f"{g}.{key}[{j + 1}]"] for j in range(d.size)]
            )
        follower = data["followers"][who - 1]
        follower["faults"] = [*follower.get("faults", []), fault]
        params.update({f"{g}.follower": who, f"{g}.type": kind})
        params.update({f"{g}.{key}": v for key, v in fault.items() if key != "type"})


def uniform_points(seed: int, start: int, count: int, ndim: int) -> np.ndarray:
    """Baseline points ``start .. start + count - 1``: point k from ``SeedSequence([seed, 1, k])``,
    the same whatever was evaluated before (so a resumed run draws the same points).

    Parameters
    ----------
    seed : int
        The search's seed.
    start, count : int
        Which points.
    ndim : int
        Dimensions of the box.
    """
    rows = [
        np.random.default_rng(np.random.SeedSequence([seed, 1, k])).uniform(size=ndim)
        for k in range(start, start + count)
    ]
    return np.array(rows).reshape(count, ndim)


def sobol_points(seed: int, start: int, count: int, ndim: int) -> np.ndarray:
    """Exploration points ``start .. start + count - 1`` of a scrambled Sobol' sequence
    seeded from ``SeedSequence([seed, 2])``: a prefix of one fixed sequence, so a resumed
    or extended search draws the same points, and a stream apart from the baseline's.

    Parameters
    ----------
    seed : int
        The search's seed.
    start, count : int
        Which points.
    ndim : int
        Dimensions of the box.
    """
    from scipy.stats import qmc

    end = start + count
    if count <= 0:
        return np.zeros((0, ndim))
    engine = qmc.Sobol(d=ndim, scramble=True, seed=np.random.default_rng([seed, 2]))
    m = max(int(np.ceil(np.log2(end))), 0)
    return engine.random_base2(m)[start:end]
