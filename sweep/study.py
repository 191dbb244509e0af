"""Study files: a base scenario, distributions over its fields, random graphs and operator inputs.

:func:`load_study` reads and completely validates a study file (docs/studies.md); every
problem is one line naming the file, the key and the fix (:class:`StudyError`). The
values are read by :mod:`sweep.study_fields`, the distributions by
:mod:`sweep.distributions`, the ``[graph]``, ``[faults]`` and ``[operator]`` families by
:mod:`sweep.families`; this module reads the file, the base scenario, ``[set]`` and
``[params]``, and checks that every key applies to the base.
"""

from __future__ import annotations

import copy
import hashlib
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import ExpressionError, ScenarioError
from core.faults import FAULT_TYPES
from core.files import FileRefused, read_regular_file
from core.overrides import set_path
from core.reading import ReadingContext
from core.scenario import MAX_SCENARIO_BYTES, load_scenario, scenario_from_dict, scenario_name
from sweep.distributions import Distribution, distribution, representative
from sweep.families import (
    FAULT_KEYS,
    FaultFamily,
    GraphFamily,
    OperatorFamily,
    fault_family,
    graph_family,
    operator_family,
    substitute,  # noqa: F401 - re-exported: search/space.py imports it from here
)
from sweep.graphs import cyclic_keys, random_graph, resize_followers
from sweep.study_fields import StudyError, join_key, read_integer, read_string, read_table

#: largest study file read (bytes)
MAX_STUDY_BYTES = 1 << 20
#: deepest nesting of tables and arrays in a study file (``[set.a.b]`` is depth 3)
MAX_DEPTH = 32
#: longest study name: sample names ``<name>-<id>`` stay within the scenario's 100
MAX_NAME = 40
#: most samples a study may ask for
MAX_COUNT = 1_000_000
TOP_KEYS = {
    "name",
    "description",
    "base",
    "count",
    "seed",
    "set",
    "params",
    "graph",
    "operator",
    "faults",
    "compare_gains",
}
#: a ``--set`` key: dotted names, each with an optional 1-based [index]
KEY_PATTERN = r"[A-Za-z_]\w*(\[\d+\])?(\.[A-Za-z_]\w*(\[\d+\])?)*"


@dataclass(frozen=True)
class Study:
    """A validated study file.

    Attributes
    ----------
    name : str
        The study's name (default: the file's stem); samples are ``<name>-<id>``.
    path : str
        The study file.
    description : str
        Free text.
    base : str
        Absolute path of the base scenario.
    base_data : dict
        The base scenario's table (relative trace paths made absolute); not to be mutated.
    count : int
        Number of samples (ids 0 .. count - 1).
    seed : int
        The study's seed; sample k draws from a generator seeded by (seed, k).
    fixed : dict
        ``--set`` key -> value given to every sample (``[set]``), before any draw.
    params : dict
        ``--set`` key -> :class:`Distribution`, in file order.
    graph : GraphFamily or None
        Random graphs replacing the base's [graph], or None to keep it.
    operator : OperatorFamily or None
        The operator input family, or None to keep the base's u0.
    faults : FaultFamily or None
        Random faults added to the followers, or None.
    designed : dict
        The keys of ``fixed`` that come from the base's design (its design.json, not
        overridden by ``[set]``); empty without a ``[design]`` table.
    compare_gains : bool
        Each sample runs once more with the base's own gains (:meth:`given`).
    """

    name: str
    path: str
    description: str
    base: str
    base_data: dict
    count: int
    seed: int
    params: dict[str, Distribution]
    graph: GraphFamily | None
    operator: OperatorFamily | None
    fixed: dict[str, Any] = field(default_factory=dict)
    faults: FaultFamily | None = None
    designed: dict[str, Any] = field(default_factory=dict)
    compare_gains: bool = False

    def given(self) -> Study:
        """The same study with the base scenario's own gains: ``[set]`` without the
        design's keys (the same draws, since the seeds and distributions are the same)."""
        fixed = {k: v for k, v in self.fixed.items() if k not in self.designed}
        return replace(self, fixed=fixed, designed={}, compare_gains=False)

    def fixed_for(self, N: int) -> dict[str, Any]:
        """``fixed`` for a sample of N followers: the design's per-follower keys, written
        for the base's followers, follow them as :func:`sweep.graphs.resize_followers`
        repeats them (:func:`sweep.graphs.cyclic_keys`); ``[set]``'s own keys as given.

        Parameters
        ----------
        N : int
            The sample's number of followers.
        """
        base_n = len(self.base_data["followers"])
        if not self.designed or N == base_n:
            return self.fixed
        own = {k: v for k, v in self.fixed.items() if k not in self.designed}
        return {**cyclic_keys(self.designed, base_n, N), **own}


# --------------------------------------------------------------------------- reading
def load_study(path: str | Path) -> Study:
    """Load and completely validate a study file.

    Parameters
    ----------
    path : str or Path
        The study TOML file.

    Returns
    -------
    Study
        Frozen and validated: every distribution is possible, the graph family has
        spanning trees, the base scenario loads and every ``--set`` key applies to it.

    Raises
    ------
    StudyError
        One line naming the file, the key, the problem and the fix.
    """
    return study_from_data(path, read_study_file(path))


def study_from_data(path: str | Path, data: dict) -> Study:
    """The study of a file's table (:func:`read_study_file`), completely validated.

    Search files (docs/search.md) read their own tables first and pass the rest here.

    Parameters
    ----------
    path : str or Path
        The file the table came from (names it in errors, resolves ``base``).
    data : dict
        Its top-level table: :data:`TOP_KEYS` only.
    """
    path = Path(path)
    f = str(path)
    read_table(f, data, "", TOP_KEYS, {"base", "count", "seed"})
    base, base_data = _base(f, path, data["base"])
    own = _fixed(f, data.get("set", {}))
    designed = {k: v for k, v in _designed(f, base, base_data).items() if k not in own}
    study = Study(
        name=_name(f, data, path),
        path=f,
        description=read_string(f, data.get("description", ""), "description"),
        base=base,
        base_data=base_data,
        count=read_integer(f, data["count"], "count", 1, MAX_COUNT),
        seed=read_integer(f, data["seed"], "seed", 0, 2**63 - 1),
        params=_params(f, data.get("params", {})),
        graph=graph_family(f, data["graph"]) if "graph" in data else None,
        operator=operator_family(f, path, data["operator"]) if "operator" in data else None,
        fixed={**designed, **own},
        faults=fault_family(f, data["faults"]) if "faults" in data else None,
        designed=designed,
        compare_gains=_compare_gains(f, data.get("compare_gains", False), base_data),
    )
    _check_keys_apply(study)
    return study


def read_study_file(path: str | Path) -> dict:
    """A study (or search) file's table, read within the file limits.

    Parameters
    ----------
    path : str or Path
        The TOML file: regular, at most :data:`MAX_STUDY_BYTES`, UTF-8, nested at most
        :data:`MAX_DEPTH` deep.
    """
    return _read_toml(Path(path))


def _read_toml(path: Path) -> dict:
    """The study file's table: a regular file of at most :data:`MAX_STUDY_BYTES`, UTF-8
    TOML nested at most :data:`MAX_DEPTH` deep."""
    f = str(path)
    try:
        raw = read_regular_file(path, MAX_STUDY_BYTES)
    except OSError as exc:
        raise StudyError(
            f, "(file)", f"cannot be read: {exc.strerror}", "an existing TOML file"
        ) from None
    except FileRefused as exc:
        raise StudyError(f, "(file)", str(exc), "a regular study file of at most 1 MiB") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError, RecursionError) as exc:
        raise StudyError(f, "(file)", f"malformed TOML: {exc}", "a valid TOML file") from None
    if _depth(data) > MAX_DEPTH:
        raise StudyError(
            f, "(file)", f"nests tables or arrays more than {MAX_DEPTH} deep", "a flatter file"
        )
    return data


def _depth(table: dict) -> int:
    """Nesting depth of the tables and arrays in ``table`` (``[set.a.b]`` is 3), without
    recursion."""
    deepest, stack = 0, [(v, 1) for v in table.values()]
    while stack:
        v, d = stack.pop()
        items = v.values() if isinstance(v, dict) else v if isinstance(v, list) else None
        if items is not None:
            deepest = max(deepest, d)
            stack.extend((x, d + 1) for x in items)
    return deepest


def _name(f: str, data: dict, path: Path) -> str:
    """``name`` (default the file's stem): the scenario loader's rule for names, since it
    names the folder ``out/<name>/``, and at most :data:`MAX_NAME` characters."""
    name = data.get("name", path.stem)
    try:
        scenario_name(ReadingContext(f), {"name": name}, path)
    except ScenarioError as exc:
        raise StudyError(f, "name", exc.problem, exc.expected) from None
    if len(name) > MAX_NAME:
        raise StudyError(f, "name", f"has {len(name)} characters", f"at most {MAX_NAME}")
    return name


def _base(f: str, path: Path, v: Any) -> tuple[str, dict]:
    """The base scenario: must load; its relative trace path is made absolute."""
    rel = read_string(f, v, "base")
    base = (path.parent / rel).resolve()
    if not base.exists():
        raise StudyError(
            f, "base", f"{rel} does not exist", "a scenario file relative to the study"
        )
    try:
        raw = read_regular_file(base, MAX_SCENARIO_BYTES)
    except (OSError, FileRefused) as exc:
        why = exc.strerror if isinstance(exc, OSError) else str(exc)
        raise StudyError(
            f, "base", f"{rel} {why}", "a scenario file relative to the study"
        ) from None
    try:
        load_scenario(base)
    except (ScenarioError, ExpressionError) as exc:
        raise StudyError(f, "base", f"the scenario is refused: {exc}", "a valid scenario") from None
    data = tomllib.loads(raw.decode("utf-8"))
    leader = data.get("leader", {})
    if "u0_csv" in leader:
        leader["u0_csv"] = str((base.parent / leader["u0_csv"]).resolve())
    return str(base), data


def _designed(f: str, base: str, base_data: dict) -> dict[str, Any]:
    """A base with a ``[design]`` table runs its designed gains: the keys of its design.json
    (``make design``, docs/synthesis.md, 'Design') join ``[set]`` (which may override them)."""
    if "design" not in base_data:
        return {}
    from design.run import stored_overrides

    ov = stored_overrides(base, {}, None, None)
    if ov is None:
        raise StudyError(
            f,
            "base",
            f"{base} has a [design] table but out/ holds no design of it",
            f"`make design SCENARIO={base}` first",
        )
    return ov


def _compare_gains(f: str, v: Any, base_data: dict) -> bool:
    """``compare_gains``: a boolean, true only on a base with a ``[design]`` table."""
    if not isinstance(v, bool):
        raise StudyError(f, "compare_gains", f"{v!r} is not a boolean", "true or false")
    if v and "design" not in base_data:
        raise StudyError(
            f,
            "compare_gains",
            "needs a base with a [design] table (the designed gains to compare)",
            "a base scenario with [design], or compare_gains = false",
        )
    return v


def _params(f: str, raw: Any) -> dict[str, Distribution]:
    table = read_table(f, raw, "params", set(raw) if isinstance(raw, dict) else set())
    out = {}
    for key, spec in table.items():
        where = join_key("params", key)
        if not re.fullmatch(KEY_PATTERN, key):
            raise StudyError(f, where, "is not a dotted key", 'a --set key, e.g. "followers[2].p0"')
        out[key] = distribution(f, spec, where)
    return out


def _fixed(f: str, raw: Any) -> dict[str, Any]:
    """``[set]``: dotted ``--set`` key -> the value every sample gets."""
    table = read_table(f, raw, "set", set(raw) if isinstance(raw, dict) else set())
    for key in table:
        if not re.fullmatch(KEY_PATTERN, key):
            raise StudyError(
                f, join_key("set", key), "is not a dotted key", 'a --set key, e.g. "options.sign"'
            )
    return dict(table)


# --------------------------------------------------------------------------- keys apply
def _check_keys_apply(study: Study) -> None:
    """Every ``[set]`` and ``[params]`` key applies to the base (resized to the smallest N)
    and the loader accepts its values (:func:`_check_values`); every fault type of
    ``[faults]`` is accepted with representative values.

    Other refusals of the loader depend on the drawn values and are reported per sample.
    """
    data = copy.deepcopy(study.base_data)
    if study.graph is not None:
        A, b = random_graph(
            study.graph.n_range[0], 0.0, study.graph.weight, np.random.default_rng(0)
        )
        data["graph"] = {"adjacency": A.tolist(), "pinning": b.tolist()}
        resize_followers(data, study.graph.n_range[0])
    _apply(study, data, "set", study.fixed_for(len(data["followers"])))
    fixed = copy.deepcopy(data)
    _apply(
        study,
        copy.deepcopy(data),
        "params",
        {k: representative(d) for k, d in study.params.items()},
    )
    _check_values(study, fixed)
    if study.faults is not None:
        _check_faults(study, fixed)


def _apply(study: Study, data: dict, table: str, values: dict[str, Any]) -> None:
    """``set_path`` of each value; a key that does not apply is refused naming ``table``."""
    for key, v in values.items():
        try:
            set_path(data, study.path, key, v)
        except ScenarioError as exc:
            raise StudyError(study.path, join_key(table, key), exc.problem, exc.expected) from None


def _validate(study: Study, data: dict) -> None:
    scenario_from_dict(data, path=study.path, sha256=hashlib.sha256(b"").hexdigest())


#: most values of one ``[params]`` key tried on load (a ``choice``'s options beyond are not)
MAX_TRIALS = 16


def trial_values(d: Distribution) -> list[Any]:
    """The values of ``d`` tried on load: its ends and middle (a ``normal``: the mean and
    mean +- 3 std, within ``truncate``), or a ``choice``'s options; lists when sized.

    Parameters
    ----------
    d : Distribution
        The distribution.
    """
    if d.kind == "choice":
        vals = list(d.args[:MAX_TRIALS])
    elif d.kind == "normal":
        mean, std = d.args
        lo, hi = d.truncate or (mean - 3 * std, mean + 3 * std)
        vals = [min(max(mean, lo), hi), lo, hi]
    elif d.kind == "integers":
        lo, hi = d.args
        vals = [lo, hi, (lo + hi) // 2]
    else:
        lo, hi = d.args
        vals = [lo, hi, lo + (hi - lo) / 2]
    return vals if d.size is None else [[v] * d.size for v in vals]


def _check_values(study: Study, fixed: dict) -> None:
    """A study whose every sample the loader would refuse for one key fails here.

    The base with ``[set]`` and each ``[params]`` key at its first trial value
    (:func:`trial_values`) is validated; a refusal at a key of ``[set]`` (not drawn by
    ``[params]``) fails the study, and one at a ``[params]`` key fails it when every trial
    value of that key is refused there (the other keys at values the loader accepted).
    A refusal at no key of the study depends on the families' draws: per sample.
    """
    trials = {k: trial_values(d) for k, d in study.params.items()}
    current = {k: v[0] for k, v in trials.items()}
    for _ in range(len(trials) + 1):
        exc = _refusal(study, fixed, current)
        owner = None if exc is None else _owner(study, exc.key)
        if owner is None:
            return
        table, key = owner
        if table == "set":
            raise _key_error(study, table, key, exc)
        for v in trials[key][1:]:
            other = _refusal(study, fixed, {**current, key: v})
            if other is None or _owner(study, other.key) != owner:
                current[key] = v
                break
        else:
            raise _key_error(study, table, key, exc, len(trials[key]))
    # each key moved once to an accepted value: what is left is not one key's fault


def _refusal(study: Study, fixed: dict, values: dict[str, Any]) -> ScenarioError | None:
    """The loader's refusal of the base with ``[set]`` and these ``[params]`` values."""
    data = copy.deepcopy(fixed)
    for key, v in values.items():
        set_path(data, study.path, key, copy.deepcopy(v))
    try:
        _validate(study, data)
    except ScenarioError as exc:
        return exc
    except ExpressionError:
        return None
    return None


def _parts(key: str) -> list[str]:
    """A dotted key's names without indices, and each index as its own part."""
    return [p for p in re.split(r"[.\[\]]+", key) if p]


def _owner(study: Study, error_key: str) -> tuple[str, str] | None:
    """The ``[params]`` (first) or ``[set]`` key the loader's refused key lies in or under."""
    err = _parts(error_key)
    for table, keys in (("params", study.params), ("set", study.fixed)):
        for key in keys:
            mine = _parts(key)
            n = min(len(mine), len(err))
            if n and mine[:n] == err[:n]:
                return table, key
    return None


def _key_error(study: Study, table: str, key: str, exc: ScenarioError, n: int = 1) -> StudyError:
    """The one-line error of a key every sample would be refused for."""
    if exc.problem == "unknown key":
        return StudyError(study.path, join_key(table, key), "names no scenario field", exc.expected)
    at = "" if _parts(exc.key) == _parts(key) else f"{exc.key}: "
    every = f" at each of its {n} trial values" if n > 1 else ""
    problem = f"every sample would be refused{every}: {at}{exc.problem}"
    return StudyError(study.path, join_key(table, key), problem, exc.expected)


def _check_faults(study: Study, data: dict) -> None:
    """Each fault type, with representative values, on the first follower it may hit."""
    fam = study.faults
    N = len(data["followers"])
    if fam.followers is not None and max(fam.followers) > N:
        raise StudyError(
            study.path,
            "faults.followers",
            f"follower {max(fam.followers)} > N = {N} (the smallest graph)",
            f"followers in 1..{N}",
        )
    i = (fam.followers or (1,))[0] - 1
    for ty in fam.types:
        trial = copy.deepcopy(data)
        fault = {"type": ty, **{k: representative(fam.keys[k]) for k in FAULT_TYPES[ty][1:]}}
        trial["followers"][i]["faults"] = [*trial["followers"][i].get("faults", []), fault]
        try:
            _validate(study, trial)
        except ScenarioError as exc:
            m = re.search(r"faults\[\d+\]\.(\w+)$", exc.key)
            if m and m.group(1) in FAULT_KEYS:
                raise StudyError(
                    study.path,
                    join_key("faults", m.group(1)),
                    f"a {ty} fault: {exc.problem}",
                    exc.expected,
                ) from None
        except ExpressionError:
            pass
