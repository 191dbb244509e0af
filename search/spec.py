"""Search files: a study's space, the search's settings and the requirements (docs/search.md).

A search file is a study file (docs/studies.md: ``base``, ``seed``, ``[set]``,
``[params]``, ``[faults]``, ``[operator]``; ``count`` optional) with a ``[search]`` table
and one ``[[requirements]]`` entry per requirement. :func:`load_search` checks all of it;
a bad field gives one line naming the file, the field and the fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from search.space import dimensions
from search.stl import FormulaError, Node, parse
from sweep import study as ST
from sweep.study_fields import read_integer, read_string, read_table

SEARCH_KEYS = {"budget", "baseline", "batch", "sigma", "explore", "minimise_steps", "seed"}
REQUIREMENT_KEYS = {"name", "formula", "scale", "guaranteed", "claims"}
#: signals a formula may name: the maxima over followers, and each follower's own (suffix i)
SIGNALS = ("deviation", "et", "eeta", "u")
MAX_BUDGET = 100_000
#: defaults of ``[search] sigma`` and ``explore`` (docs/search.md, 'Running a search')
SIGMA = 0.1
EXPLORE = 0.3


@dataclass(frozen=True)
class Requirement:
    """One requirement.

    Attributes
    ----------
    name : str
        Its name in the results (column ``rob:<name>``) and the report.
    formula : str
        The STL formula (:mod:`search.stl`); empty for a guaranteed-rows requirement.
    scale : float
        Robustness is divided by it, so requirements of different units compare.
    guaranteed : bool
        Every ``guaranteed`` row of the bound table as ``observed <= bound``.
    claims : tuple of str
        With ``guaranteed``: only rows of these claim ids (empty: all).
    node : Node or None
        The parsed formula.
    """

    name: str
    formula: str
    scale: float
    guaranteed: bool
    claims: tuple[str, ...]
    node: Node | None


@dataclass(frozen=True)
class SearchSettings:
    """The ``[search]`` table.

    Attributes
    ----------
    budget : int
        Evaluations of the optimiser (CMA-ES).
    baseline : int
        Evaluations of uniform random search in the same run.
    batch : int or None
        Optimiser population per generation (default: 4 per worker, at least 6; at least 4, the
        least population CMA-ES recombines).
    sigma : float
        CMA-ES initial step size in the unit box.
    explore : float
        Share of the budget spent on the Sobol' exploration that starts the optimisers.
    minimise_steps : int
        Bisection steps per parameter when minimising the least robust run.
    seed : int
        Seed of the optimiser and the baseline (default the study's seed).
    """

    budget: int
    baseline: int
    batch: int | None
    sigma: float
    minimise_steps: int
    seed: int
    explore: float = EXPLORE


@dataclass(frozen=True)
class SearchFile:
    """A loaded search file.

    Attributes
    ----------
    path : str
        The file.
    study : sweep.study.Study
        Its space (the study part).
    settings : SearchSettings
        ``[search]``.
    requirements : tuple of Requirement
        ``[[requirements]]``, in file order.
    """

    path: str
    study: ST.Study
    settings: SearchSettings
    requirements: tuple[Requirement, ...]

    @property
    def name(self) -> str:
        """The output folder's name, ``out/<name>/``."""
        return self.study.name


def _err(f: str, key: str, problem: str, fix: str) -> ST.StudyError:
    return ST.StudyError(f, key, problem, fix)


#: ``[search]`` keys a command line may replace (``python -m search run --seed``)
OVERRIDABLE = ("seed", "budget", "baseline")


def load_search(path: str | Path, overrides: dict[str, int] | None = None) -> SearchFile:
    """Load and validate a search file.

    Parameters
    ----------
    path : str or Path
        The TOML file.
    overrides : dict, optional
        Values of :data:`OVERRIDABLE` keys replacing the file's ``[search]`` values before
        they are checked (a seed sweep runs one file).

    Raises
    ------
    sweep.study.StudyError
        One line: ``file: key: problem (expected fix)``.
    """
    path = Path(path)
    f = str(path)
    data = ST.read_study_file(path)
    search = data.pop("search", None)
    reqs = data.pop("requirements", None)
    if search is None:
        raise _err(f, "search", "missing", "a [search] table with budget and baseline")
    for key, value in (overrides or {}).items():
        if key not in OVERRIDABLE:
            raise _err(f, f"search.{key}", "cannot be overridden", f"one of {OVERRIDABLE}")
        if isinstance(search, dict):
            search = {**search, key: value}
    if not reqs:
        raise _err(f, "requirements", "missing", "at least one [[requirements]] entry")
    settings = _settings(f, search, data)
    data.setdefault("count", max(1, settings.budget + settings.baseline))
    study = ST.study_from_data(path, data)  # the study part, by the study's own checks
    if study.graph is not None:
        raise _err(f, "graph", "random graphs are not searchable", "a study without [graph]")
    if study.operator is not None and study.operator.traces:
        raise _err(f, "operator.traces", "recorded traces are not searchable", "[operator] u0")
    if not dimensions(study):
        raise _err(
            f,
            "params",
            "nothing to vary: the study's space has no dimension to search",
            "a [params] entry, a [faults] family or [operator] params",
        )
    n = len(study.base_data.get("followers", []))
    signals = {*SIGNALS, *(f"{s}{i}" for s in SIGNALS for i in range(1, n + 1))}
    if not isinstance(reqs, list) or not all(isinstance(r, dict) for r in reqs):
        raise _err(f, "requirements", "not an array of tables", "[[requirements]] entries")
    out = tuple(_requirement(f, k, r, signals) for k, r in enumerate(reqs, 1))
    names = [r.name for r in out]
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise _err(f, "requirements.name", f"{dup[0]!r} given twice", "distinct names")
    return SearchFile(f, study, settings, out)


def _settings(f: str, raw: Any, data: dict) -> SearchSettings:
    t = read_table(f, raw, "search", SEARCH_KEYS, {"budget", "baseline"})
    batch = t.get("batch")
    sigma = t.get("sigma", SIGMA)
    if isinstance(sigma, bool) or not isinstance(sigma, int | float) or not 0 < sigma <= 1:
        raise _err(f, "search.sigma", f"is {sigma!r}", "a number in (0, 1] (unit box)")
    explore = t.get("explore", EXPLORE)
    if isinstance(explore, bool) or not isinstance(explore, int | float) or not 0 <= explore <= 0.9:
        raise _err(f, "search.explore", f"is {explore!r}", "a share of the budget in [0, 0.9]")
    seed = t.get("seed", data.get("seed", 0))
    return SearchSettings(
        budget=read_integer(f, t["budget"], "search.budget", 1, MAX_BUDGET),
        baseline=read_integer(f, t["baseline"], "search.baseline", 0, MAX_BUDGET),
        batch=None if batch is None else read_integer(f, batch, "search.batch", 4, 4096),
        sigma=float(sigma),
        minimise_steps=read_integer(f, t.get("minimise_steps", 3), "search.minimise_steps", 0, 20),
        seed=read_integer(f, seed, "search.seed", 0, 2**63 - 1),
        explore=float(explore),
    )


def _requirement(f: str, k: int, raw: dict, signals: set[str]) -> Requirement:
    key = f"requirements[{k}]"
    t = read_table(f, raw, key, REQUIREMENT_KEYS, {"name"})
    name = read_string(f, t["name"], f"{key}.name")
    if not name or not all(c.isalnum() or c in "-_." for c in name):
        raise _err(f, f"{key}.name", f"is {name!r}", "letters, digits, '-', '_', '.'")
    guaranteed = t.get("guaranteed", False)
    if not isinstance(guaranteed, bool):
        raise _err(f, f"{key}.guaranteed", f"is {guaranteed!r}", "true or false")
    formula = t.get("formula")
    if guaranteed == (formula is not None):
        raise _err(f, key, "needs exactly one of formula and guaranteed = true", "one of them")
    scale = t.get("scale", 1.0)
    if (
        isinstance(scale, bool)
        or not isinstance(scale, int | float)
        or not (math.isfinite(scale) and scale > 0)
    ):
        raise _err(f, f"{key}.scale", f"is {scale!r}", "a finite number > 0")
    claims = t.get("claims", [])
    if not guaranteed and claims:
        raise _err(f, f"{key}.claims", "given without guaranteed = true", "guaranteed = true")
    if not isinstance(claims, list) or not all(isinstance(c, str) for c in claims):
        raise _err(f, f"{key}.claims", f"is {claims!r}", "a list of claim ids")
    node = None
    if formula is not None:
        formula = read_string(f, formula, f"{key}.formula")
        try:
            node = parse(formula, signals)
        except FormulaError as exc:
            raise _err(f, f"{key}.formula", str(exc), "a formula of docs/search.md") from None
    return Requirement(name, formula or "", float(scale), guaranteed, tuple(claims), node)
