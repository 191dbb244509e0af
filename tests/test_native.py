"""The native driver's toolchain (generated/native.py) and the generated sparse LU
(generated/sparse_lu.py) its kernels factorise with.

Independent truth: numpy's dense solve and determinant for the generated sparse LU. The
driver's runs (generated/native/agents.c) are tested in tests/test_agents.py against
the symbolic closed loop and CasADi's CVODES.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from core.errors import BuildError
from generated import native
from generated.codegen import cache_key
from generated.sparse_lu import sparse_lu
from generated.values import CodegenSettings, IntegratorSettings

E = ca.SX(0, 1)


def ode(name: str, t: ca.SX, x: ca.SX, rhs: ca.SX) -> ca.Function:
    return ca.Function(name, [t, x, E, E, E], [rhs, E, E, E], ca.dyn_in(), ca.dyn_out())


@pytest.fixture(scope="module")
def cg(tmp_path_factory):
    return CodegenSettings(optimization="-O0", build_root=str(tmp_path_factory.mktemp("nbuild")))


# --------------------------------------------------------------------------- sparse LU
def random_pattern(rng, n: int, density: float) -> tuple[ca.Sparsity, np.ndarray]:
    mask = rng.random((n, n)) < density
    np.fill_diagonal(mask, True)
    r, c = np.nonzero(mask)
    A = np.zeros((n, n))
    A[r, c] = rng.standard_normal(len(r))
    A += np.diag(np.abs(A).sum(axis=1) + 1.0)  # diagonally dominant: no pivoting needed
    return ca.Sparsity.triplet(n, n, r.tolist(), c.tolist()), A


@pytest.mark.parametrize(("n", "density"), [(1, 1.0), (6, 0.5), (25, 0.1), (40, 0.06)])
@pytest.mark.parametrize("reciprocal", [False, True])
def test_sparse_lu_solves_like_numpy_and_pivots_give_the_determinant(n, density, reciprocal):
    rng = np.random.default_rng(n)
    for _ in range(3):
        sp, A = random_pattern(rng, n, density)
        lu = sparse_lu(sp, reciprocal=reciprocal)
        LU, piv = lu.factor(ca.project(ca.DM(A), sp))
        # the stored diagonal: U's pivots, or their reciprocals
        diag = np.diag(np.array(ca.DM(LU)))
        p = np.array(piv).ravel()
        np.testing.assert_allclose(diag * p if reciprocal else diag / p, 1.0, rtol=1e-14)
        b = rng.standard_normal(n)
        x = np.array(lu.solve(LU, b)).ravel()
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-11, atol=1e-13)
        # U's diagonal: the product of the pivots is det(A) (no row exchanges)
        sign, logdet = np.linalg.slogdet(A)
        p = np.array(piv).ravel()
        assert np.prod(np.sign(p)) == sign
        assert np.sum(np.log(np.abs(p))) == pytest.approx(logdet, rel=1e-11, abs=1e-11)
        assert lu.fill == LU.nnz() - sp.nnz() >= 0


def test_sparse_lu_fill_is_zero_for_a_triangular_pattern():
    n = 8
    r, c = np.tril_indices(n)
    lu = sparse_lu(ca.Sparsity.triplet(n, n, r.tolist(), c.tolist()))
    assert lu.fill == 0


def test_sparse_lu_rejects_a_pattern_without_its_diagonal():
    sp = ca.Sparsity.triplet(2, 2, [0, 1], [1, 0])
    with pytest.raises(BuildError, match="diagonal"):
        sparse_lu(sp)
    with pytest.raises(BuildError, match="square"):
        sparse_lu(ca.Sparsity.dense(2, 3))


# --------------------------------------------------------------------------- toolchain
def test_toolchain_key_covers_every_header_and_library():
    tc = native.toolchain()
    headers = {str(p.relative_to(native.INCLUDE_DIR)) for p in native.INCLUDE_DIR.rglob("*.h")}
    assert set(tc.key["headers"]) == headers and "sundials/sundials_config.h" in headers
    assert len(tc.key["libraries"]) == len(native.SUNDIALS_LIBRARIES) == len(tc.libraries)
    assert "hitl_agents_run" in tc.appended_source and "hitl_native_check" in tc.appended_source
    # a changed header (or library) changes the cache key: the stale build is never used
    changed = dict(tc.key, headers=dict(tc.key["headers"], **{"sundials/x.h": "0"}))
    s = CodegenSettings()
    assert cache_key("int x;", s, tc.key) != cache_key("int x;", s, changed)


def test_missing_scikit_sundae_is_a_one_line_build_error(monkeypatch):
    native.toolchain.cache_clear()
    monkeypatch.setattr(native.importlib.util, "find_spec", lambda name: None)
    try:
        with pytest.raises(BuildError, match="scikit-sundae") as ei:
            native.toolchain()
        assert "\n" not in str(ei.value)
    finally:
        native.toolchain.cache_clear()


def test_settings_accept_native():
    s = IntegratorSettings(method="native")
    assert dataclasses.replace(s, rtol=1e-9).method == "native"
