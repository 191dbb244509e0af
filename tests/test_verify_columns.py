"""The verification's fast paths give what the plain ones give, and never serve stale data.

- ``verify.signals.Columns`` (one float array of the frame) selects the same numbers, in
  the same memory order, as pandas' column selection, and the bounds table built through
  it equals the one built through pandas' own selection (a frame with a text column takes
  that path);
- ``verify.lyapunov.evaluate_p`` calls the map on numpy memory: its outputs equal a
  closed-form evaluation and the call with CasADi matrices bit for bit, including a
  structurally zero output; a repeated evaluation is reused only for identical inputs;
- ``core.graph.pinned_laplacian`` (kept by value) equals D − A + B computed by hand and
  hands out independent copies;
- the study's row summaries equal values worked out by hand.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pandas as pd
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from core.graph import pinned_laplacian
from sweep.measures import summarize_table, tail_max_et
from verify import lyapunov as L
from verify import signals as S
from verify.bounds import provable_entry_time, theorem2_constants
from verify.synthetic import synthetic_trajectory
from verify.table import COLUMNS, bounds_table


@pytest.fixture(scope="module")
def frame() -> pd.DataFrame:
    return synthetic_trajectory()


def test_columns_select_what_pandas_selects(frame):
    cols = S.Columns.of(frame)
    assert S.Columns.of(cols) is cols
    for names in (["p1_1", "p1_2"], ["V1"], ["et5_2", "t", "phi3"]):
        want = frame[names].to_numpy(dtype=float)
        got = S.take(cols, names)
        assert got.tobytes() == want.tobytes()
        # rows vary fastest in memory in both: numpy reduces them in the same order
        assert got.flags["F_CONTIGUOUS"] and want.strides[0] == got.strides[0] == 8
    assert np.array_equal(S.column(cols, "V1"), frame["V1"].to_numpy(float))
    assert np.array_equal(S.block(cols, "chi", 3, 2), S.block(frame, "chi", 3, 2))
    assert S.dims(cols) == S.dims(frame)
    assert S.has(cols, "V2_5") and not S.has(cols, "V2_6")
    with pytest.raises(S.VerifyError, match="et6_1"):
        S.block(cols, "et", 6, 2)
    with pytest.raises(KeyError):
        S.column(cols, "nope")


def test_columns_of_a_frame_with_text_read_each_request_from_pandas(frame):
    df = frame.assign(label="x")
    cols = S.Columns.of(df)
    assert cols.values is None
    assert np.array_equal(S.take(cols, ["u2_1", "u2_2"]), frame[["u2_1", "u2_2"]].to_numpy())


def test_bounds_table_is_the_same_through_pandas_selection(frame, paper_scenario):
    """The array path against pandas' selection (text column) and a reordered frame."""
    want = bounds_table(paper_scenario, frame.assign(label="x"))
    assert list(want.columns) == COLUMNS and len(want) > 50
    pd.testing.assert_frame_equal(bounds_table(paper_scenario, frame), want, check_exact=True)
    shuffled = frame[list(reversed(frame.columns))]
    pd.testing.assert_frame_equal(bounds_table(paper_scenario, shuffled), want, check_exact=True)


def _toy_function() -> ca.Function:
    """(t, x, p) -> (p0 |x|² + t, (x1 p1, structural 0), sin x) with x in R³."""
    t, x, p = ca.SX.sym("t"), ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    second = ca.SX(2, 1)
    second[0] = x[0] * p[1]  # second[1] stays a structural zero
    return ca.Function(
        "toy",
        [t, x, p],
        [p[0] * ca.sumsqr(x) + t, second, ca.sin(x)],
        ["t", "x", "p"],
        ["a", "b", "c"],
    )


def _layout(a: np.ndarray) -> list[int]:
    """Strides of the axes longer than 1 (a length-1 axis's stride means nothing)."""
    return [st for st, n in zip(a.strides, a.shape, strict=True) if n > 1]


def test_evaluate_p_equals_closed_form_and_the_matrix_call():
    L.clear_cache()
    f = _toy_function()
    entry = L.FastFunctions({"toy": f}, key="toy")
    rng = np.random.default_rng(7)
    t, X, p = np.linspace(0.0, 1.0, 9), rng.normal(size=(9, 3)), np.array([2.0, -3.0])
    a, b, c = L.evaluate_p(entry, "toy", t, X, p)
    assert a.shape == (9, 1, 1) and b.shape == (9, 2, 1) and c.shape == (9, 3, 1)
    np.testing.assert_allclose(a[:, 0, 0], 2.0 * np.sum(X**2, axis=1) + t, rtol=1e-14)
    np.testing.assert_array_equal(b[:, 0, 0], -3.0 * X[:, 0])
    np.testing.assert_array_equal(b[:, 1, 0], 0.0)
    np.testing.assert_allclose(c[:, :, 0], np.sin(X), rtol=1e-14)
    # the same map called with CasADi matrices, as before the buffer path
    ref = f.map("m", "serial", 9, [2], []).call([ca.DM(t.reshape(1, -1)), ca.DM(X.T), ca.DM(p)])
    for got, want in zip((a, b, c), L._blocks(f, ref, 9), strict=True):
        assert got.tobytes() == want.tobytes()
        assert _layout(got) == _layout(want)  # the same memory order for any reduction


def test_evaluate_p_reuses_only_identical_inputs():
    L.clear_cache()
    entry = L.FastFunctions({"toy": _toy_function()}, key="toy")
    t, X, p = np.linspace(0.0, 1.0, 5), np.ones((5, 3)), np.array([1.0, 1.0])
    first = L.evaluate_p(entry, "toy", t, X, p)
    first[0][:] = -1.0  # a caller's changes do not reach the next caller
    assert np.all(L.evaluate_p(entry, "toy", t, X, p)[0] > 0)
    X2 = X.copy()
    X2[3, 1] = np.nextafter(1.0, 2.0)  # one ulp in one state: evaluated again
    a2 = L.evaluate_p(entry, "toy", t, X2, p)[0][:, 0, 0]
    assert a2[3] == 1.0 * (2.0 + np.nextafter(1.0, 2.0) ** 2) + t[3]
    assert np.array_equal(a2[[0, 1, 2, 4]], 3.0 + t[[0, 1, 2, 4]])
    p2 = np.array([2.0, 1.0])
    assert np.array_equal(L.evaluate_p(entry, "toy", t, X, p2)[0][:, 0, 0], 6.0 + t)


def _laplacian_by_hand(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.diag(np.abs(A).sum(axis=1)) - A + np.diag(b)


def test_pinned_laplacian_by_value_and_copies():
    rng = np.random.default_rng(3)
    for N in (3, 5, 8):
        A = rng.choice([-1.0, 0.0, 0.5, 2.0], size=(N, N))
        np.fill_diagonal(A, 0.0)
        b = rng.choice([0.0, 1.0], size=N)
        for adjacency in (A, A.tolist(), sp.csc_matrix(A), sp.coo_matrix(A)):
            got = pinned_laplacian(adjacency, b)
            assert isinstance(got, sp.csr_matrix)
            assert np.array_equal(got.toarray(), _laplacian_by_hand(A, b))
        got.data[:] = 99.0  # the caller's copy only
        assert np.array_equal(pinned_laplacian(A, b).toarray(), _laplacian_by_hand(A, b))
        A[0, 1] += 1.0  # the same array changed in place: a new value, a new matrix
        assert np.array_equal(pinned_laplacian(A, b).toarray(), _laplacian_by_hand(A, b))


def test_summarize_table_by_hand():
    rows = [
        ("formation.leader", "Formation |p_i - h_i y0 - R| (tail sup)", "1", "info", 0.5, True),
        (
            "formation.leader",
            "Formation |p_i - h_i y0 - R| (tail sup)",
            "2",
            "info",
            math.nan,
            True,
        ),
        ("formation.leader", "Formation |p_i - h_i y0 - R| (tail sup)", "3", "info", 0.75, True),
        ("t1.tail", "T1 |ebar_eta_i| -> 0 (tail sup)", "1", "info", 1e-3, True),
        ("effort.peak", "peak |u_i|", "1", "info", 40.0, True),
        ("effort.peak_late", "peak |u_i| after t = 1 s", "1", "info", 90.0, True),
        ("effort.peak_late", "peak |u_i| after t = 1 s", "2", "info", 50.0, True),
        ("effort.demanded_late", "peak |u_i*| after t = 1 s", "1", "info", 60.0, True),
        ("effort.demanded_late", "peak |u_i*| after t = 1 s", "2", "info", 100.0, True),
        ("t2.chi.provable", "T2 provable", "2", "guaranteed", 1.0, False),
        ("t1.dv1.supported", "T1 dV1/dt", "all", "guaranteed", 1.0, False),
        ("def1.derived", "Def. 1 derived", "4", "guaranteed", 1.0, True),
        ("t2.eq38", "consistency: (38)", "1", "consistency", 1.0, True),
    ]
    table = pd.DataFrame(
        [
            dict(zip(COLUMNS[:11], (c, a, "", k, 1.0, o, o, h, "[0, 1] s", "", i), strict=True))
            for i, c, a, k, o, h in rows
        ]
    )
    assert summarize_table(table) == {
        "formation_tail_max": 0.75,
        "observer_tail_max": 1e-3,
        "peak_u_max": 40.0,
        "peak_u_late": 90.0,
        "demanded_u_late": 100.0,
        "effort_over_demand": 1.5,  # follower 1: 90 / 60 (follower 2: 50 / 100)
        "guaranteed_held": False,
        "guaranteed_failed": "T2 provable (follower 2); T1 dV1/dt",
        "consistency_held": True,
        "n_guaranteed": 3,
        "n_consistency": 1,
    }
    empty = summarize_table(table.iloc[:0])
    assert math.isnan(empty["formation_tail_max"]) and empty["guaranteed_held"]


def test_tail_max_et_of_the_synthetic_errors(frame):
    """e_ti = c_i e^{-2t}: the tail's largest norm is max_i |c_i| e^{-2 t_s} at its start."""
    t = frame["t"].to_numpy()
    ts = t[S.tail_mask(t, 0.5)][0]
    c = [np.hypot(5.0 + i, -3.0 + 0.5 * i) for i in range(5)]
    assert tail_max_et(frame, 0.5) == pytest.approx(max(c) * math.exp(-2.0 * ts), rel=1e-12)
    # the runner's frames are read by position; a text column takes pandas' path
    assert tail_max_et(frame.assign(label="x"), 0.5) == tail_max_et(frame, 0.5)


def test_provable_entry_time_from_a_restart_row(frame, paper_scenario):
    """t_c from V2 at row k: the comparison lemma's time from that value, by its formula."""
    c = theorem2_constants(paper_scenario, 2)
    V2 = frame["V2_3"].to_numpy()
    for k in (0, 700):
        x = c.Omega_var * 0.5 * V2[k] / (c.chi_v_var * 0.5)  # Omega(1-delta)V/(chi_v delta)
        want = 0.0 if x <= 1.0 else math.log(x) / c.Omega_var
        for df in (frame, S.Columns.of(frame)):
            assert provable_entry_time(c, df, 2, 0.5, row=k) == pytest.approx(want, rel=1e-14)
        assert provable_entry_time(c, frame.iloc[k:], 2, 0.5) == provable_entry_time(
            c, frame, 2, 0.5, row=k
        )


def test_theorem2_entry_of_unprovable_followers_is_lemma1_observed_time(monkeypatch):
    # the bounds table names agents as text ("2"); an unprovable follower's entry time is
    # its own row's observed Lemma 1 reaching time, worked out here by hand
    import types

    import verify.bounds as B
    from sweep.measures import theorem2_entry

    monkeypatch.setattr(
        B, "theorem2_constants", lambda sc, i, cfg: types.SimpleNamespace(provable=False)
    )
    rows = [
        ("Lemma 1 reaching time t_f (s)", str(a), "info", t, True) for a, t in ((1, 0.4), (2, 2.5))
    ]
    table = pd.DataFrame(
        [
            dict(
                zip(
                    COLUMNS[:11],
                    (c, a, "", k, 1.0, o, o, h, "[0, 1] s", "", "lemma1.paper"),
                    strict=True,
                )
            )
            for c, a, k, o, h in rows
        ]
    )
    sc = types.SimpleNamespace(N=3)
    got = theorem2_entry(table, sc, None, types.SimpleNamespace(lemma1_delta=0.1))
    assert got["t2_entry:1"] == 0.4 and got["t2_entry:2"] == 2.5
    assert math.isnan(got["t2_entry:3"]) and got["t2_entry_source"] == "Lemma 1 observed"


# ------------------------------------------ coverage on arrays against the pandas reading
def _reference_coverage(table: pd.DataFrame, t0: float, t1: float) -> dict:
    """The coverage columns read with pandas' own filters, a follower's rows a sub-frame:
    the plain form of ``sweep.coverage.coverage_columns`` (and of the headline's coverage)."""
    from verify import claims as CL
    from verify.headline import _fraction, _gaps, _step, by_agent
    from verify.rows import held_mask

    groups, out = by_agent(table), {}
    tol = 1e-9 * max(1.0, abs(t1))
    for a in sorted(int(k) for k in groups if k.isdigit()):
        rows = groups[str(a)]
        g = rows[rows["kind"] == CL.Kind.GUARANTEED.value]
        track, env = g[g["claim_id"].isin(CL.TRACKING)], g[g["claim_id"].isin(CL.ENVELOPE)]

        def wins(r):
            return [
                (float(x), float(y))
                for x, y in zip(r["t_start"], r["t_end"], strict=True)
                if math.isfinite(x) and math.isfinite(y)
            ]

        w, we = wins(track), wins(env)
        end = g[np.abs(g["t_end"].astype(float) - t1) <= tol]
        ids = set(end["claim_id"])
        last = end[end["claim_id"].isin(CL.TRACKING)]
        ult = math.nan
        if {CL.T2_CHI.id, CL.DEF1_DERIVED.id} <= set(last["claim_id"]) and held_mask(last).all():
            ult = float(last["t_start"].astype(float).max())
        out[a] = {
            "held": int(held_mask(g).sum()),
            "total": len(g),
            "tracking": len(track),
            "envelope": len(env),
            "covered": _fraction(w, t0, t1),
            "covered_any": _fraction(w + we, t0, t1),
            "gaps": tuple(_gaps(rows, w, t0, t1, _step(table))),
            "last_covered": bool(ids & {CL.T2_CHI.id, CL.T2_CHI_ENV.id})
            and bool(ids & {CL.DEF1_DERIVED.id, CL.DEF1_ENV.id}),
            "ultimate_from": ult,
        }
    return out


_CLAIMS = ["t2.chi.provable", "def1.derived", "t2.e.provable", "t2.chi.envelope"]
_CLAIMS += ["def1.envelope", "t1.tail"]


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["1", "2", "all"]),
            st.sampled_from(["guaranteed", "guaranteed", "guaranteed", "paper", "info"]),
            st.sampled_from(_CLAIMS),
            st.sampled_from([0.0, 0.5, 2.5, 7.0, math.nan]),  # window starts
            st.sampled_from([2.5, 2.51, 10.0, 10.0, 10.0, math.nan]),  # and ends
            st.sampled_from([True, True, False, None]),
        ),
        min_size=1,
        max_size=24,
    )
)
def test_coverage_on_arrays_equals_the_pandas_reading(rows):
    """``TableColumns`` masks give what pandas' filters of a follower's sub-frame give: every
    count, share, gap and the study's coverage columns (NaN windows, missing verdicts)."""
    from sweep.coverage import coverage_columns
    from verify.headline import coverage, ultimate_from

    table = pd.DataFrame(
        {
            "agent": [r[0] for r in rows],
            "kind": [r[1] for r in rows],
            "claim_id": [r[2] for r in rows],
            "t_start": [r[3] for r in rows],
            "t_end": [r[4] for r in rows],
            "holds": pd.array([r[5] for r in rows], dtype="boolean"),
            "note": ["not guaranteed: x" if r[5] is None else "" for r in rows],
        }
    )
    t0 = float(np.nanmin(table["t_start"])) if table["t_start"].notna().any() else 0.0
    t1 = float(np.nanmax(table["t_end"])) if table["t_end"].notna().any() else 10.0
    want = _reference_coverage(table, t0, t1)
    got = coverage(table, (t0, t1))
    assert [c.agent for c in got] == sorted(want)
    for c in got:
        w = want[c.agent]
        assert (c.held, c.total, c.tracking, c.envelope) == (
            w["held"],
            w["total"],
            w["tracking"],
            w["envelope"],
        )
        assert (c.covered, c.covered_any, c.gaps) == (w["covered"], w["covered_any"], w["gaps"])
        assert _same(ultimate_from(table, c.agent, t1), w["ultimate_from"])
    if not table["t_start"].notna().any() or not table["t_end"].notna().any():
        return
    cols = coverage_columns(table)
    for a, w in want.items():
        assert cols[f"covered:{a}"] == w["covered"]
        assert cols[f"last_covered:{a}"] == w["last_covered"]
        assert _same(cols[f"ultimate_from:{a}"], w["ultimate_from"])


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


def test_mark_switching_notes_the_rows_a_switch_voids(frame, paper_scenario):
    """The rows ``mark_switching`` turns to ``info`` and the notes it puts first, row by row
    against the rule written out (claims on the base graph; paper rows whose window holds
    a switch)."""
    import dataclasses

    from core.graph import Switch
    from verify import claims as CL
    from verify.table import SWITCHING_NOTE, mark_switching

    table = bounds_table(paper_scenario, frame)
    switches = (Switch(time=3.0, follower=1, neighbour=None, weight=0.0),)
    graph = dataclasses.replace(paper_scenario.graph, switches=switches)
    sc = dataclasses.replace(paper_scenario, graph=graph)
    got = mark_switching(table, sc)
    assert list(got.columns) == list(table.columns) and (got.dtypes == table.dtypes).all()
    changed = 0
    for k in range(len(table)):
        before, after = table.iloc[k], got.iloc[k]
        base = CL.depends(before["claim_id"], CL.Dep.BASE_GRAPH)
        inside = before["kind"] == "paper" and before["t_start"] <= 3.0 <= before["t_end"]
        if base or inside:
            changed += 1
            assert after["kind"] == "info"
            assert after["note"].startswith(SWITCHING_NOTE)
            tail = after["note"].split(")", 1)[1]
            assert tail == (f"; {before['note']}" if before["note"] else "")
        else:
            assert after.equals(before)
    assert changed > 0
    pd.testing.assert_frame_equal(mark_switching(table, paper_scenario), table)
