"""The gains a run uses: ``out/<name>/gains.json`` reused when it is this scenario's, else synthesized."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from core.artifacts import OUT_ROOT, sha256_file
from core.errors import SynthesisError
from core.memo import MEMO
from core.models import cache
from core.scenario import Scenario
from synthesis.gains import Gains, gains_from_dict, read_gains_file, recertified, save_gains


@dataclass(frozen=True)
class GainsInfo:
    """Where the gains came from: ``path``, ``sha256`` of gains.json, ``reused``, ``seconds``."""

    path: Path
    sha256: str
    reused: bool
    seconds: float


#: gains synthesized in this process, by :func:`synthesis_inputs` key
_SYNTHESIZED = MEMO.namespace("synthesized-gains", 256)  # core/memo.py
#: observer settings synthesis does not read (the observer's runtime numbers)
_NOT_SYNTHESIS = ("alpha1", "alpha1_bar", "phi0", "phi_min")
#: build-cache sub-folder of synthesized gains, ``<cache root>/gains/<synthesis_inputs>.json``
CACHE_KIND = "gains"
#: packages whose numbers the synthesized gains depend on (solver, linear algebra)
_SYNTHESIS_PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel")


def synthesis_inputs(sc: Scenario) -> str:
    """SHA-256 of what synthesis reads: the leader's matrices and bound, the graph, the observer.

    Scenarios with equal keys get the same gains (a study's samples that vary only
    controller gains, faults, offsets or initial states synthesize once).

    Parameters
    ----------
    sc : Scenario
    """
    L, G, o = sc.leader, sc.graph, sc.observer
    obs = {f.name: getattr(o, f.name) for f in dataclasses.fields(o)}
    parts = {
        "A0": L.A0,
        "B0": L.B0,
        "C0": L.C0,
        "alpha": L.alpha,
        "adjacency": G.adjacency,
        "pinning": G.pinning,
        "switches": [dataclasses.astuple(s) for s in G.switches],
        **{k: v for k, v in obs.items() if k not in _NOT_SYNTHESIS},
    }
    text = json.dumps(
        {k: np.asarray(v).tolist() if v is not None else None for k, v in parts.items()},
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()


@MEMO.memoize("synthesis-code-sha256", 1)
def synthesis_code() -> str:
    """SHA-256 of the code synthesis runs: ``synthesis/*.py``, ``core/graph.py`` and versions.

    A disk entry made by other code (or another solver version) is not this code's
    result, so it is recomputed rather than reused.
    """
    import core.graph
    import synthesis

    files = sorted(Path(synthesis.__file__).parent.glob("*.py")) + [Path(core.graph.__file__)]
    h = hashlib.sha256()
    for f in files:
        h.update(f.name.encode() + b"\0" + hashlib.sha256(f.read_bytes()).digest())
    for pkg in _SYNTHESIS_PACKAGES:
        try:
            h.update(f"{pkg}={version(pkg)}\0".encode())
        except PackageNotFoundError:
            h.update(f"{pkg}=none\0".encode())
    return h.hexdigest()


def cached_gains(sc: Scenario, key: str, root: Path | None = None) -> Gains | None:
    """Gains synthesized earlier for inputs ``key``, re-certified for ``sc``; else None.

    The entry is refused (None) when it is missing, not this key's or this code's
    (:func:`synthesis_code`), malformed, or when :func:`synthesis.gains.recertified`
    finds a mismatch with ``sc`` or a failed certificate check.

    Parameters
    ----------
    sc : Scenario
    key : str
        ``synthesis_inputs(sc)``.
    root : Path, optional
        Build cache root; default ``$HITL_BUILD_DIR`` or the user cache folder.
    """
    body = cache.read_entry(CACHE_KIND, key, root)
    if body is None or body.get("code") != synthesis_code():
        return None
    source = str(cache.entry_path(CACHE_KIND, key, root))
    try:
        return recertified(gains_from_dict(body.get("gains"), source=source), source, sc)
    except SynthesisError:
        return None


def store_gains(gains: Gains, key: str, root: Path | None = None) -> Path | None:
    """Keep synthesized ``gains`` under ``key`` in the build cache (None if unwritable).

    Parameters
    ----------
    gains : Gains
    key : str
        ``synthesis_inputs`` of the scenario they were synthesized for.
    root : Path, optional
        Build cache root; default ``$HITL_BUILD_DIR`` or the user cache folder.
    """
    body = {"code": synthesis_code(), "gains": gains.to_json_dict()}
    try:
        return cache.write_entry(CACHE_KIND, key, body, root)
    except OSError:  # an unwritable cache costs the next process a synthesis, no more
        return None


def ensure_gains(sc: Scenario, out_root: str | Path | None = None) -> tuple[Gains, GainsInfo]:
    """Read ``out/<name>/gains.json`` if it belongs to this scenario, else synthesize and write it.

    The file belongs to the scenario when its ``scenario_sha256`` equals ``sc.sha256``;
    it is then re-certified (:func:`synthesis.gains.recertified`: it must match the
    scenario and pass every certificate check not confined to scenario-given gains).
    A malformed or failing file is refused in one line, whatever ``STRICT`` says.
    Gains this process synthesized for equal :func:`synthesis_inputs` are re-certified
    for ``sc`` and reused instead of solving the LMIs again; so are gains another
    process synthesized, kept in the build cache (:func:`cached_gains`).

    Parameters
    ----------
    sc : Scenario
        The scenario (``name`` picks the folder, ``sha256`` decides reuse).
    out_root : str or Path, optional
        Output root; default ``out/`` (``$HITL_OUT``).

    Returns
    -------
    (Gains, GainsInfo)
    """
    path = Path(out_root or OUT_ROOT) / sc.name / "gains.json"
    t0 = time.perf_counter()
    if path.is_file():
        gf = read_gains_file(path)  # a malformed file is refused, never overwritten
        if gf.scenario_sha256 == sc.sha256:  # reused only after a fresh certificate
            gains = recertified(gf.gains, str(path), sc)
            _SYNTHESIZED.setdefault(synthesis_inputs(sc), gains)
            return gains, GainsInfo(path, gf.sha256, True, time.perf_counter() - t0)
    gains = scenario_gains(sc, str(path))
    save_gains(gains, path)
    return gains, GainsInfo(path, sha256_file(path), False, time.perf_counter() - t0)


def _synthesize(sc: Scenario, where: str) -> Gains:
    """Solve the LMIs for ``sc``; cvxpy is imported only here, when no gains can be reused."""
    try:
        from synthesis import synthesize
    except ImportError:
        raise SynthesisError(
            f"{where}: missing or stale and synthesis.synthesize is not available (run make synth)"
        ) from None
    return synthesize(sc)


def scenario_gains(sc: Scenario, where: str = "gains") -> Gains:
    """Gains certified for ``sc`` without a gains.json of its own (what :func:`ensure_gains`
    writes when the scenario's file is absent or stale).

    Gains this process synthesized for equal :func:`synthesis_inputs` are re-certified
    for ``sc``; else those another process kept in the build cache (:func:`cached_gains`,
    certified on reading); else the LMIs are solved. A study's in-memory sample takes
    its gains from here: nothing reads a file of them.

    Parameters
    ----------
    sc : Scenario
    where : str
        Names the gains in messages (the file they are for).
    """
    key = synthesis_inputs(sc)
    if key in _SYNTHESIZED:  # same synthesis inputs: re-certified for this scenario
        gains = recertified(_SYNTHESIZED[key], f"{where} (synthesized in this process)", sc)
    elif (gains := cached_gains(sc, key)) is not None:  # another process synthesized them
        _SYNTHESIZED[key] = gains
    else:
        gains = _SYNTHESIZED[key] = _synthesize(sc, where)
        store_gains(gains, key)
    if gains.info.get("scenario_sha256") != sc.sha256:  # variants carry their own hash
        gains = dataclasses.replace(gains, info={**gains.info, "scenario_sha256": sc.sha256})
    return gains
