"""``verify.signals.TrajectoryView`` reads a trajectory's named blocks.

- on a small hand-built frame (N = 2, n = 2, m = 3, so the width rules differ) every
  accessor returns exactly the arrays the frame was built from, in the layout of pandas'
  own selection, and the norms equal numpy's on that selection bit for bit;
- a missing column raises the one-line ``VerifyError`` naming it;
- each ``Signal`` has its width rule, and the columns of all of them are the writer's
  (``generated.trajectory_file.column_names``), in its order;
- no module of ``verify/`` or ``sweep/`` (besides ``verify/signals.py``) spells a
  trajectory column from a prefix: no f-string column
  name, no prefix-string call of the column helpers (the scan is shown to catch planted
  examples).
"""

from __future__ import annotations

import re
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from verify.signals import Dims, Signal, TrajectoryView, VerifyError, leader_column

ROOT = Path(__file__).resolve().parents[1]
K, N, n, m = 5, 2, 2, 3
WIDTH = {"n": n, "m": m, "1": 1}
#: each signal's width rule, written out
RULES = {
    Signal.P: "n",
    Signal.Q: "n",
    Signal.ETA: "m",
    Signal.MU: "m",
    Signal.PHI: "1",
    Signal.THETAHAT: "n",
    Signal.GHAT: "1",
    Signal.U: "n",
    Signal.B: "n",
    Signal.ET: "n",
    Signal.EETA: "m",
    Signal.CHI: "n",
    Signal.V2: "1",
}
#: the column stems as trajectory.csv spells them (one-column signals have no ``_r``)
STEMS = {
    Signal.P: "p",
    Signal.Q: "q",
    Signal.ETA: "eta",
    Signal.MU: "mu",
    Signal.PHI: "phi",
    Signal.THETAHAT: "thetahat",
    Signal.GHAT: "ghat",
    Signal.U: "u",
    Signal.B: "b",
    Signal.ET: "et",
    Signal.EETA: "eeta",
    Signal.CHI: "chi",
    Signal.V2: "V2_",
}


def _hand_built() -> tuple[pd.DataFrame, dict]:
    """A frame in the trajectory.csv format and the arrays its columns were made from."""
    rng = np.random.default_rng(27)
    arrays: dict = {"t": np.linspace(0.0, 1.0, K), "eta0": rng.normal(size=(K, m))}
    cols: dict[str, np.ndarray] = {"t": arrays["t"]}
    for k in range(m):
        cols[f"eta0_{k + 1}"] = arrays["eta0"][:, k]
    for i in range(1, N + 1):
        for sig, stem in STEMS.items():
            x = rng.normal(size=(K, WIDTH[RULES[sig]]))
            arrays[sig, i] = x
            if RULES[sig] == "1":
                cols[f"{stem}{i}"] = x[:, 0]
            else:
                for r in range(x.shape[1]):
                    cols[f"{stem}{i}_{r + 1}"] = x[:, r]
    arrays["V1"] = rng.normal(size=K)
    cols["V1"] = arrays["V1"]
    return pd.DataFrame(cols), arrays


@pytest.fixture(scope="module")
def built() -> tuple[pd.DataFrame, dict]:
    return _hand_built()


def test_the_view_returns_the_columns_it_was_built_from(built):
    df, arrays = built
    view = TrajectoryView.of(df)
    assert TrajectoryView.of(view) is view and len(view) == K
    assert view.dims == Dims(N=N, n=n, m=m)
    assert np.array_equal(view.t, arrays["t"]) and view.t.shape == (K,)
    assert np.array_equal(view.leader(), arrays["eta0"])
    assert np.array_equal(view.leader(2), arrays["eta0"][:, :2])
    assert np.array_equal(view.V1(), arrays["V1"]) and view.has_V1()
    C0 = np.array([[1.0, 0.5, -2.0], [0.0, 3.0, 1.0]])
    assert np.array_equal(view.leader_output(C0), arrays["eta0"] @ C0.T)
    for i in range(1, N + 1):
        for sig, stem in STEMS.items():
            got, want = view.block(sig, i), arrays[sig, i]
            assert got.shape == (K, WIDTH[RULES[sig]]) and np.array_equal(got, want)
            names = [c for c in df.columns if re.fullmatch(rf"{stem}{i}(_\d+)?", c)]
            pandas = df[names].to_numpy(dtype=float)
            # pandas' selection, byte for byte and in its column-major layout
            assert got.tobytes() == pandas.tobytes() and got.flags["F_CONTIGUOUS"]
            assert view.norm(sig, i).tobytes() == np.linalg.norm(pandas, axis=1).tobytes()
            assert view.has(sig, i)
            if RULES[sig] == "1":
                assert np.array_equal(view.scalar(sig, i), want[:, 0])
            else:
                with pytest.raises(ValueError, match=sig.name):
                    view.scalar(sig, i)
    phi = np.stack([arrays[Signal.PHI, i][:, 0] for i in range(1, N + 1)], 1)
    assert np.array_equal(view.scalars(Signal.PHI), phi)
    assert np.array_equal(view.block(Signal.ET, 2, 1), arrays[Signal.ET, 2][:, :1])
    assert not view.has(Signal.P, N + 1)


def test_a_missing_column_is_a_verify_error_naming_it(built):
    df, _ = built
    view = TrajectoryView.of(df.drop(columns=["et2_2", "V2_1", "V1", "eta0_3"]))
    with pytest.raises(VerifyError, match=r"^trajectory: column 'et2_2' is missing") as e:
        view.block(Signal.ET, 2)
    assert "\n" not in str(e.value)  # a one-line message
    with pytest.raises(VerifyError, match="'et2_2'"):
        view.norm(Signal.ET, 2)
    with pytest.raises(VerifyError, match="'V2_1'"):
        view.scalar(Signal.V2, 1)
    with pytest.raises(VerifyError, match="'V2_1'"):
        view.scalars(Signal.V2)
    with pytest.raises(VerifyError, match="'V1'"):
        view.V1()
    with pytest.raises(VerifyError, match="'eta0_3'"):
        view.leader(3)
    with pytest.raises(VerifyError, match="'p3_1'"):
        view.block(Signal.P, 3)
    assert not view.has(Signal.V2, 1) and not view.has_V1()
    assert view.block(Signal.ET, 1).shape == (K, n)  # the rest still reads
    with pytest.raises(VerifyError, match="'t'"):
        _ = TrajectoryView.of(df.drop(columns=["t"])).t
    with pytest.raises(VerifyError, match="'p1_1' is missing"):
        _ = TrajectoryView.of(df[["t", "eta0_1"]]).dims


@pytest.mark.parametrize("sig", list(Signal), ids=lambda s: s.name)
def test_each_signal_has_its_width_rule(sig):
    dm = Dims(N=N, n=n, m=m)
    assert sig.rule == RULES[sig] and sig.width(dm) == WIDTH[RULES[sig]]
    assert sig.stem == STEMS[sig] and Signal.named(sig.stem) is sig
    names = sig.columns(2, sig.width(dm))
    if sig.rule == "1":
        assert names == [f"{STEMS[sig]}2"] == [sig.column(2)]
    else:
        assert names == [f"{STEMS[sig]}2_{r}" for r in range(1, sig.width(dm) + 1)]


def test_the_signals_are_the_writers_columns():
    from generated.trajectory_file import column_names

    sc = types.SimpleNamespace(N=3, n=2, m=4)
    dm = Dims(N=sc.N, n=sc.n, m=sc.m)
    mine = ["t", *(leader_column(k) for k in range(1, sc.m + 1))]
    for i in range(1, sc.N + 1):
        for sig in Signal:
            mine += sig.columns(i, sig.width(dm))
    assert [*mine, "V1"] == column_names(sc)
    with pytest.raises(VerifyError, match="'xi'"):
        Signal.named("xi")


# ---- no consumer spells a column from a prefix ----------------------------------------

#: the names of the trajectory's columns before their number
_STEM = r"(?:eta0_|p|q|eta|mu|phi|thetahat|ghat|u|b|et|eeta|chi|V2_)"
OFFENCES = (
    re.compile(rf"""\bf["']{_STEM}\{{"""),  # f"et{i}_{r}", f"eta0_{k}", f"V2_{i}"
    re.compile(r"""\b(?:block|agent_norm)\(\s*[\w.]+\s*,\s*f?["']"""),  # block(df, "p", ...)
    re.compile(r"""\b(?:column|take|has)\(\s*[\w.]+\s*,\s*(?:\[\s*)?f["']"""),  # take(df, [f"..."])
)
#: the view and the column helpers it builds on
EXEMPT = {"verify/signals.py"}


def offences(text: str) -> list[str]:
    """The lines of ``text`` that spell a trajectory column from a prefix."""
    return [ln.strip() for ln in text.splitlines() if any(p.search(ln) for p in OFFENCES)]


def _modules() -> list[Path]:
    files = sorted([*ROOT.glob("verify/*.py"), *ROOT.glob("sweep/*.py")])
    return [f for f in files if f.relative_to(ROOT).as_posix() not in EXEMPT]


@pytest.mark.parametrize(
    "bad",
    [
        'p = S.block(df, "p", i + 1, dm.n)',
        'e = S.agent_norm(df, "et", i + 1, n)',
        'if S.has(df, f"u{i + 1}_1"):',
        'eta0 = S.take(df, [f"eta0_{k}" for k in range(1, m + 1)])',
        'V2 = S.column(df, f"V2_{agent + 1}")',
        'cols = [f"phi{j + 1}" for j in range(N)]',
        'col = f"et{i}_{r}"',
        "g = frame[f'ghat{i}']",
    ],
)
def test_the_scan_catches_a_planted_column_name(bad, tmp_path):
    assert offences(bad) == [bad]
    planted = tmp_path / "planted.py"
    planted.write_text(Path(ROOT / "verify/effort.py").read_text() + f"\n{bad}\n")
    assert offences(planted.read_text()) == [bad]


@pytest.mark.parametrize(
    "good",
    [
        "p = view.block(S.Signal.P, i + 1)",
        "e = view.norm(S.Signal.ET, i + 1, n)",
        'f"phi_min = {sc.observer.phi_min:g}."',
        'f"V2(0) = {V2[0]:.4g}, level {level:.4g}; "',
        'f"peak |u_i| after t = {startup:g} s"',
        "t = view.t",
    ],
)
def test_the_scan_leaves_reads_by_signal_alone(good):
    assert offences(good) == []


def test_no_module_spells_a_column_from_a_prefix():
    files = _modules()
    names = {f.relative_to(ROOT).as_posix() for f in files}
    assert {"verify/table.py", "verify/theorem2_rows.py", "sweep/measures.py"} <= names
    found = {f.relative_to(ROOT).as_posix(): bad for f in files if (bad := offences(f.read_text()))}
    assert found == {}, "read these through verify.signals.TrajectoryView / Signal"
