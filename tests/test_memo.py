"""The per-process cache (core/memo.py): least-recently-used eviction per namespace, one
lock, and no module-level cache dict anywhere else in the packages.
"""

from __future__ import annotations

import re
import threading
from pathlib import Path

import pytest

from core.memo import MEMO, ProcessCache

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (
    "core",
    "synthesis",
    "symbolic",
    "generated",
    "verify",
    "design",
    "sweep",
    "search",
    "console",
)
#: module-level mappings that are registries (filled once by registration), not caches
REGISTRIES = {
    "core/models/base.py": {"REGISTRY"},
    "generated/solvers/__init__.py": {"_REGISTRY"},
    "verify/claims.py": {"REGISTRY", "_BY_TEXT"},
}
DICT_AT_MODULE_LEVEL = re.compile(
    r"^(_?[A-Za-z][A-Za-z0-9_]*)(?:\s*:[^=]+)?\s*=\s*"
    r"(?:\{\}|dict\(\)|(?:collections\.)?OrderedDict\(\)|(?:collections\.)?defaultdict\()",
    re.M,
)


def test_least_recently_used_is_evicted_at_capacity():
    ns = ProcessCache().namespace("t", 3)
    for k in "abc":
        ns[k] = k.upper()
    assert ns["a"] == "A"  # a read makes it the most recent
    ns["d"] = "D"  # evicts b, the least recently used
    assert "b" not in ns and list(ns) == ["c", "a", "d"]
    assert ns.setdefault("c", "x") == "C" and list(ns) == ["a", "d", "c"]
    ns["e"] = "E"
    assert list(ns) == ["d", "c", "e"] and len(ns) == 3
    assert ns.get("missing", 7) == 7 and ns.pop("d") == "D" and ns.pop("d", None) is None
    with pytest.raises(KeyError):
        ns["d"]


def test_namespaces_are_declared_once_and_cleared_together():
    pc = ProcessCache()
    a, b = pc.namespace("a", 2), pc.namespace("b", 5)
    assert pc.namespace("a", 2) is a
    with pytest.raises(ValueError, match="capacity 2, not 3"):
        pc.namespace("a", 3)
    with pytest.raises(ValueError, match=">= 1"):
        pc.namespace("c", 0)
    a[1], b[1], b[2] = 1, 1, 2
    assert pc.sizes() == {"a": (1, 2), "b": (2, 5)}
    pc.clear()
    assert len(a) == len(b) == 0


def test_threads_never_see_more_than_the_capacity():
    ns = ProcessCache().namespace("threads", 16)
    errors = []

    def work(j):
        for k in range(2000):
            ns[(j, k)] = k
            got = ns.get((j, k))
            if got not in (k, None) or len(ns) > 16:
                errors.append((j, k, got, len(ns)))

    threads = [threading.Thread(target=work, args=(j,)) for j in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == [] and len(ns) == 16


def test_every_stage_cache_is_a_namespace_of_the_one_object():
    import generated.agent_kernels  # noqa: F401 - declare their namespaces
    import generated.loaded  # noqa: F401
    import generated.trajectory_file  # noqa: F401
    import symbolic.closed_loop  # noqa: F401
    import synthesis.certificate  # noqa: F401
    import synthesis.gains_cache  # noqa: F401
    import verify.lyapunov  # noqa: F401

    names = set(MEMO.sizes())
    assert {
        "agent-kernels",
        "synthesized-gains",
        "compiled-builds",
        "mapped-outputs",
        "parametric-loops",
        "certificates",
        "verify-functions",
        "verify-last-evaluation",
    } <= names


def _module_level_dicts(text: str) -> set[str]:
    return set(DICT_AT_MODULE_LEVEL.findall(text))


def test_no_module_level_cache_dict_outside_the_cache_object():
    found = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            hits = _module_level_dicts(path.read_text()) - REGISTRIES.get(rel, set())
            if hits:
                found[rel] = sorted(hits)
    assert found == {}, f"module-level dicts (use core.memo.MEMO.namespace): {found}"


def test_the_grep_catches_planted_caches():
    planted = "_SEEN: dict[str, int] = {}\nBIG = OrderedDict()\nx = f({})\n    _inner = {}\n"
    assert _module_level_dicts(planted) == {"_SEEN", "BIG"}


FUNCTOOLS_CACHE = re.compile(
    r"lru_cache|functools\.cache\b|^\s*@cache\b|from functools import[^\n]*\bcache\b", re.M
)


def test_no_functools_cache_outside_the_cache_object():
    # a functools cache would be a second eviction rule and a second clear
    found = []
    for pkg in (*PACKAGES, "benchmarks"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if FUNCTOOLS_CACHE.search(path.read_text()):
                found.append(path.relative_to(ROOT).as_posix())
    assert found == [], f"functools caches (use core.memo.MEMO.memoize): {found}"
    planted = "from functools import lru_cache\n\n@lru_cache(maxsize=4)\ndef f(x): ...\n"
    assert FUNCTOOLS_CACHE.search(planted) and FUNCTOOLS_CACHE.search("@cache\ndef g(): ...")
    assert not FUNCTOOLS_CACHE.search("from core.models import cache\n")


def test_memoize_remembers_by_arguments_and_evicts_like_any_namespace():
    cache, calls = ProcessCache(), []

    @cache.memoize("squares", 2)
    def square(x: float, *, shift: float = 0.0) -> float:
        calls.append(x)
        return x * x + shift

    assert [square(2.0), square(2.0), square(3.0), square(2.0, shift=1.0)] == [4.0, 4.0, 9.0, 5.0]
    assert calls == [2.0, 3.0, 2.0]  # the repeated call was remembered
    assert len(square.namespace) == 2  # capacity 2: the least recent, square(2.0), went
    square(2.0)
    assert calls == [2.0, 3.0, 2.0, 2.0]
    square.cache_clear()
    assert len(square.namespace) == 0
