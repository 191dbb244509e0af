"""Build-cache tiers of a fresh process: synthesized gains and model derivations on disk.

Independent truths: a direct call of ``synthesis.synthesize`` (the gains a disk entry
must reproduce), the derivation run without the cache and the paper's closed-form M, C,
G (what a cached model must evaluate to), and the certificate (what a tampered entry
must fail). Every test uses its own build root under ``tmp_path``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from helpers import TWO_LINK_PAPER as PAPER
from helpers import two_link_closed_form

import synthesis.api
from core.models import build_model, cache, derive
from core.scenario import load_scenario
from synthesis import gains_cache
from synthesis.gains import Gains, gains_from_dict

ROOT = Path(__file__).resolve().parents[1]
SYNTH = ROOT / "scenarios" / "paper-synth.toml"


@pytest.fixture
def build_root(tmp_path, monkeypatch):
    """A private build root (``HITL_BUILD_DIR``) and empty in-process memos."""
    root = tmp_path / "build"
    monkeypatch.setenv("HITL_BUILD_DIR", str(root))
    monkeypatch.setattr(gains_cache, "_SYNTHESIZED", {})
    derive._build_cached.cache_clear()
    yield root
    derive._build_cached.cache_clear()


@pytest.fixture(scope="module")
def synth_scenario():
    return load_scenario(SYNTH)


@pytest.fixture(scope="module")
def reference_gains(synth_scenario):
    """The gains of a plain synthesis, no cache involved."""
    return synthesis.api.synthesize(synth_scenario)


@pytest.fixture
def count_synthesis(monkeypatch):
    """Counts the LMI syntheses ``ensure_gains`` runs."""
    calls = []
    real = synthesis.api.synthesize

    def counted(sc, **kw):
        calls.append(sc.name)
        return real(sc, **kw)

    monkeypatch.setattr(synthesis.api, "synthesize", counted)
    return calls


def fresh_gains(sc, out: Path) -> Gains:
    """``ensure_gains`` as a new process sees it: no memo, no out/<name>/gains.json."""
    gains_cache._SYNTHESIZED.clear()
    return gains_cache.ensure_gains(sc, out)[0]


def assert_same_gains(a: Gains, b: Gains) -> None:
    """Every field equal: numbers bit for bit, ``info`` and the certificate's every entry."""
    for f in fields(Gains):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.shape == y.shape and np.array_equal(x, y), f.name
        else:
            assert x == y, f.name
    assert b.certificate["checks"] and all(c["passed"] for c in b.certificate["checks"])


# --------------------------------------------------------------------------- gains
def test_gains_from_disk_equal_synthesized_ones(
    build_root, tmp_path, synth_scenario, reference_gains, count_synthesis
):
    first = fresh_gains(synth_scenario, tmp_path / "out1")
    assert count_synthesis == [synth_scenario.name]
    key = gains_cache.synthesis_inputs(synth_scenario)
    assert (build_root / "gains" / f"{key}.json").is_file()
    second = fresh_gains(synth_scenario, tmp_path / "out2")
    assert count_synthesis == [synth_scenario.name]  # read from disk, not solved again
    assert_same_gains(reference_gains, first)
    assert_same_gains(reference_gains, second)


def _stored(build_root: Path, key: str) -> Path:
    return build_root / "gains" / f"{key}.json"


@pytest.mark.parametrize("damage", ["garbage", "edited_number", "truncated"])
def test_a_corrupted_gains_entry_is_ignored_and_rewritten(
    build_root, tmp_path, synth_scenario, reference_gains, count_synthesis, damage
):
    fresh_gains(synth_scenario, tmp_path / "out1")
    path = _stored(build_root, gains_cache.synthesis_inputs(synth_scenario))
    text = path.read_text()
    if damage == "garbage":
        path.write_bytes(b"\x00\xff\x93garbage")
    elif damage == "edited_number":  # the body no longer matches its checksum
        d = json.loads(text)
        d["body"]["gains"]["lambda1"] *= 1.5
        path.write_text(json.dumps(d))
    else:
        path.write_text(text[: len(text) // 2])
    got = fresh_gains(synth_scenario, tmp_path / "out2")
    assert len(count_synthesis) == 2  # recomputed
    assert_same_gains(reference_gains, got)
    assert (
        path.read_text() != ""
        and json.loads(path.read_text())["body"]["gains"] == json.loads(text)["body"]["gains"]
    )


def test_a_number_that_breaks_the_certificate_is_refused(
    build_root, tmp_path, synth_scenario, reference_gains, count_synthesis
):
    fresh_gains(synth_scenario, tmp_path / "out1")
    key = gains_cache.synthesis_inputs(synth_scenario)
    body = cache.read_entry("gains", key)
    # λ1 w > λ̄1 (Theorem 1) fails; the checksum is made valid so only the certificate refuses
    body["gains"]["lambda1"] = 1e-6
    cache.write_entry("gains", key, body)
    assert gains_cache.cached_gains(synth_scenario, key) is None
    got = fresh_gains(synth_scenario, tmp_path / "out2")
    assert len(count_synthesis) == 2
    assert_same_gains(reference_gains, got)


def test_an_entry_under_the_wrong_key_is_refused(
    build_root, tmp_path, synth_scenario, reference_gains
):
    other = load_scenario(ROOT / "scenarios" / "paper.toml")  # gives Q, λ1, λ2
    key, other_key = (gains_cache.synthesis_inputs(s) for s in (synth_scenario, other))
    assert key != other_key
    fresh_gains(synth_scenario, tmp_path / "out1")
    # copied file: its recorded key is not its name
    _stored(build_root, other_key).write_bytes(_stored(build_root, key).read_bytes())
    assert cache.read_entry("gains", other_key) is None
    # re-keyed with a valid checksum: the recertification finds the scenario's own Q
    cache.write_entry("gains", other_key, cache.read_entry("gains", key))
    assert cache.read_entry("gains", other_key) is not None
    assert gains_cache.cached_gains(other, other_key) is None


def test_an_entry_of_other_synthesis_code_is_refused(build_root, tmp_path, synth_scenario):
    fresh_gains(synth_scenario, tmp_path / "out1")
    key = gains_cache.synthesis_inputs(synth_scenario)
    assert gains_cache.cached_gains(synth_scenario, key) is not None
    body = cache.read_entry("gains", key)
    cache.write_entry("gains", key, {**body, "code": "0" * 64})
    assert gains_cache.cached_gains(synth_scenario, key) is None


def test_reusing_cached_gains_imports_no_solver_control_or_matplotlib(
    build_root, tmp_path, synth_scenario
):
    """A fresh process that reuses cached gains, certificate included (what a study's
    worker does for its first sample), imports neither cvxpy nor the plotting stack."""
    fresh_gains(synth_scenario, tmp_path / "out1")
    code = (
        "import sys; from pathlib import Path; from core.scenario import load_scenario\n"
        "from synthesis import gains_cache as g\n"
        f"sc = load_scenario({str(SYNTH)!r})\n"
        "k = g.synthesis_inputs(sc); assert g.cached_gains(sc, k) is not None\n"
        "g.scenario_gains(sc)  # certified on reuse, or it raises\n"
        "heavy = ('cvxpy', 'clarabel', 'scipy.stats', 'control', 'matplotlib', 'sympy')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


# --------------------------------------------------------------------------- models
def _derive_forbidden(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("derived although the cache holds the model")

    monkeypatch.setattr(derive, "_derive", boom)


def test_cached_model_equals_the_derivation_and_the_closed_forms(build_root, monkeypatch):
    M, C, G, p, q, D = derive._symbolic("two_link", tuple(sorted(PAPER.items())))
    assert D is None  # the paper's arm has no dissipation
    direct = {
        "M": derive._to_casadi(M, [p], ["p"], "M"),
        "C": derive._to_casadi(C, [p, q], ["p", "q"], "C"),
        "G": derive._to_casadi(G, [p], ["p"], "G"),
    }
    bounds = derive._mass_bounds(M, p, "two_link")
    first = build_model("two_link", PAPER)
    assert len(list((build_root / "models").glob("*.json"))) == 1
    derive._build_cached.cache_clear()
    _derive_forbidden(monkeypatch)
    cached = build_model("two_link", PAPER)
    assert cached.M_bounds == first.M_bounds == bounds
    assert cached.checks == first.checks == {"property1": "exact", "property2": "exact"}
    rng = np.random.default_rng(3)
    for _ in range(20):
        pv, qv = rng.uniform(-4, 4, 2), rng.uniform(-3, 3, 2)
        Mx, Cx, Gx = two_link_closed_form(pv, qv, **PAPER)
        got = {
            "M": cached.M(pv).full(),
            "C": cached.C(pv, qv).full(),
            "G": cached.G(pv).full().ravel(),
        }
        want = {
            "M": direct["M"](pv).full(),
            "C": direct["C"](pv, qv).full(),
            "G": direct["G"](pv).full().ravel(),
        }
        for k in got:
            assert np.array_equal(got[k], want[k]), k  # bit for bit
        np.testing.assert_allclose(got["M"], Mx, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(got["C"], Cx, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(got["G"], Gx, rtol=1e-13, atol=1e-12)
    assert cached.sympy_M == M  # the sympy form is still there, derived on demand


def _model_entry(build_root: Path) -> Path:
    (path,) = (build_root / "models").glob("*.json")
    return path


@pytest.mark.parametrize("damage", ["garbage", "edited_number", "swapped_functions", "bad_bounds"])
def test_a_corrupted_model_entry_is_ignored_and_rewritten(build_root, damage):
    first = build_model("two_link", PAPER)
    path = _model_entry(build_root)
    key = path.stem
    good = path.read_bytes()
    body = cache.read_entry("models", key)
    if damage == "garbage":
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + good[:40])
    elif damage == "edited_number":  # checksum no longer matches
        d = json.loads(good)
        d["body"]["M_bounds"][0] = 100.0
        path.write_text(json.dumps(d))
    elif damage == "swapped_functions":  # valid checksum, wrong signatures
        fs = body["functions"]
        cache.write_entry("models", key, {**body, "functions": {**fs, "M": fs["C"]}})
    else:
        cache.write_entry("models", key, {**body, "M_bounds": [float("nan"), 1.0]})
    derive._build_cached.cache_clear()
    again = build_model("two_link", PAPER)
    assert again.M_bounds == first.M_bounds
    assert again.M.serialize() == first.M.serialize()
    assert path.read_bytes() == good  # rewritten as the derivation gives it


def test_a_model_entry_under_another_key_is_refused(build_root, monkeypatch):
    build_model("two_link", PAPER)
    path = _model_entry(build_root)
    other = {**PAPER, "m2": 2.5}
    other_key = derive.model_key("two_link", tuple(sorted(other.items())))
    (build_root / "models" / f"{other_key}.json").write_bytes(path.read_bytes())
    assert cache.read_entry("models", other_key) is None  # recorded key is not its name
    # re-keyed with a valid checksum: the parameters it records are not these
    cache.write_entry("models", other_key, cache.read_entry("models", path.stem))
    derive._build_cached.cache_clear()
    mdl = build_model("two_link", other)
    pv = np.array([0.3, -1.1])
    Mx, _, _ = two_link_closed_form(pv, np.zeros(2), **other)
    np.testing.assert_allclose(mdl.M(pv).full(), Mx, rtol=1e-13)


def test_model_key_changes_with_parameters_and_model():
    items = tuple(sorted(PAPER.items()))
    k = derive.model_key("two_link", items)
    assert k == derive.model_key("two_link", items)
    assert k != derive.model_key("two_link", tuple(sorted({**PAPER, "J1": 5.0 + 1e-15}.items())))
    assert k != derive.model_key("point_mass_2d", (("m", 1.5),))


def test_the_cache_root_is_the_build_caches(monkeypatch, tmp_path):
    from core.build_cache import default_build_root

    monkeypatch.setenv("HITL_BUILD_DIR", str(tmp_path))
    assert cache.entry_path("models", "k") == tmp_path / "models" / "k.json"
    monkeypatch.delenv("HITL_BUILD_DIR")
    assert cache.entry_path("models", "k") == default_build_root() / "models" / "k.json"


def test_an_unwritable_cache_still_gives_the_model(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("HITL_BUILD_DIR", str(blocker))
    derive._build_cached.cache_clear()
    try:
        mdl = build_model("two_link", PAPER)
    finally:
        derive._build_cached.cache_clear()
    pv = np.array([0.7, 0.2])
    np.testing.assert_allclose(mdl.M(pv).full(), two_link_closed_form(pv, pv, **PAPER)[0])


def test_gains_cache_round_trip_is_exact(reference_gains):
    """The JSON form of the gains reads back to the same numbers (repr keeps every digit)."""
    d = json.loads(json.dumps(reference_gains.to_json_dict()))
    back = gains_from_dict(d)
    for f in fields(Gains):
        x = getattr(reference_gains, f.name)
        if isinstance(x, np.ndarray):
            assert np.array_equal(x, getattr(back, f.name)), f.name


def test_a_lagrangian_with_captured_values_is_not_cached(build_root):
    """Its source does not define it: two such models must never share an entry."""
    from core.models import REGISTRY, ModelSpec, register

    def make(scale):
        def lag(prm):
            import sympy as sp

            x, v = sp.symbols("x v", real=True)
            return sp.nsimplify(scale) * sp.nsimplify(prm["m"]) * v**2 / 2, 0, [x], [v]

        return lag

    try:
        for scale in (1, 3):
            register(
                ModelSpec(name="_test_scaled", n=1, defaults={"m": 2.0}, lagrangian=make(scale))
            )
            derive._build_cached.cache_clear()  # the in-process memos are keyed by name
            derive._symbolic.cache_clear()
            assert derive.model_key("_test_scaled", (("m", 2.0),)) is None
            assert build_model("_test_scaled").M_bounds == (2.0 * scale, 2.0 * scale)
    finally:
        REGISTRY.pop("_test_scaled", None)
        derive._build_cached.cache_clear()
    assert not (build_root / "models").exists()
