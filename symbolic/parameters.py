"""The closed loop's runtime parameters: numbers that are inputs, not constants, of the code.

Every number a study or the operator console may vary enters the compiled closed loop
through one flat vector ``p`` instead of being written into the generated C:

* ``agents``: the per-agent numbers (:func:`param_layout`), column i = follower i:
  the observer's decay α1 + ᾱ1 and floor φ_min, the controller's λ_ir, k1ir, k2i, γ_i,
  σ_i, ĝ_i0, the formation offset b_i0, the bias bound d_i, the actuator limit and ᾱ1i;
* ``expr:<where>``: the literals of each expression of t (the operator's u0, the health
  g_i(t) with its faults, the bias f_i(t)): ``2*cos(t)`` is the template ``#*cos(t)``
  with the parameter 2 (:meth:`core.expressions.Expr.literals`);
* ``graph``, ``graph_times``, ``graph_fade``: the nonzero weights of ``L + B`` and
  ``a0 ∘ h`` (the coupling of eq. (6)) of every topology a switching graph reaches, the
  times it switches and the time a switch's weights fade over (``graph.link_fade``; only
  with switches);
* with the graph as data (``dense=True``, a study's many graphs): ``graph`` holds every
  entry of ``L + B`` and ``a0 ∘ h``, zeros included, for at least
  :data:`DENSE_TOPOLOGIES` topologies (the last one repeated from t = ∞), and ``v1``
  the graph's coefficients of V1 (eq. (17): Lemma 3's z, the diagonal l̄ of L̄ and k1), so
  one structure serves every graph of N followers.

What is left is the *structure*: the graph's pattern (the union over its topologies)
and number of topologies (with the graph as data: only N), the follower models, the
options, the expressions' templates, the leader matrices and the certified gains.
:func:`structure_key` hashes exactly that, so two scenarios with equal keys are the
same code with different ``p`` (tests/test_parameters.py checks it against the
serialized CasADi Functions). Initial states never enter the code: x(0) is computed
from the scenario at run time.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from core.errors import ScenarioError
from core.expressions import Expr
from core.graph import pinned_laplacian
from core.scenario import Scenario
from symbolic.network import graph_matrices
from symbolic.observer import ObserverGains, gain_pattern, gain_values
from synthesis.gains import Gains

#: observer settings that are runtime parameters (in ``agents``) or only initial values
_OBSERVER_PARAMS = ("alpha1", "alpha1_bar", "phi_min", "phi0")
#: controller settings that are runtime parameters (``u_max``: only its presence is structure)
_CONTROLLER_PARAMS = ("Lambda", "k1", "k2", "gamma", "sigma", "ghat_ref", "u_max")
#: topologies the code holds at least with the graph as data: up to two links lost and
#: restored (a random-graph study's losses) need no other structure
DENSE_TOPOLOGIES = 5
#: the most followers the graph is data for: its code grows with N² (every entry of L + B),
#: at N = 20 about 40 s of gcc once per N; a larger graph keeps its own sparse code
DENSE_MAX_N = 24
#: the gains' graph-dependent numbers: runtime data (``v1``) with the graph as data
_GRAPH_GAINS = ("L_bar", "Z", "k1", "w")


@dataclass(frozen=True)
class ParamLayout:
    """Named slices of the flat parameter vector ``p``.

    Attributes
    ----------
    slices : dict
        Name -> slice of p (``"agents"``, ``"graph"``, ``"expr:<where>"``).
    size : int
        Length of p.
    dense : bool
        The graph as data (:func:`layout_of`).
    """

    slices: dict[str, slice]
    size: int
    dense: bool = False

    def get(self, p: Any, name: str) -> Any:
        """The part of ``p`` named ``name`` (numpy array or CasADi vector).

        Parameters
        ----------
        p : ndarray or casadi.SX or casadi.MX
            A parameter vector of this layout.
        name : str
            A name of :attr:`slices`.
        """
        return p[self.slices[name]]


def param_layout(n: int, saturated: bool = False) -> tuple[dict[str, slice], int]:
    """Offsets of the per-agent numbers (rows of the ``agents`` block).

    Parameters
    ----------
    n : int
        Coordinates per follower.
    saturated : bool
        Whether the scenario has an actuator limit (``controller.u_max``).
    """
    sizes = [
        ("obs", 2),  # (α1 + ᾱ1, φ_min): input of the observer Function
        ("Lambda", n),
        ("k1", n),
        ("k2", 1),
        ("gamma", 1),
        ("sigma", 1),
        ("ghat_ref", 1),
        ("b0", n),
        ("d", n),
        ("abar", 1),  # ᾱ1i: weights φ_i in V1, eq. (17)
    ]
    if saturated:
        sizes.append(("u_max", 1))
    off, k = {}, 0
    for name, s in sizes:
        off[name] = slice(k, k + s)
        k += s
    return off, k


def param_matrix(sc: Scenario) -> np.ndarray:
    """Per-agent numbers as columns (the ``agents`` block of p, npar × N).

    Parameters
    ----------
    sc : Scenario
    """
    sat = sc.controller.u_max is not None
    off, npar = param_layout(sc.n, sat)
    P = np.zeros((npar, sc.N))
    o, c = sc.observer, sc.controller
    for i, fo in enumerate(sc.followers):
        P[off["obs"], i] = (o.alpha1[i] + o.alpha1_bar[i], o.phi_min)
        P[off["Lambda"], i] = c.Lambda[i]
        P[off["k1"], i] = c.k1[i]
        P[off["k2"], i] = c.k2[i]
        P[off["gamma"], i] = c.gamma[i]
        P[off["sigma"], i] = c.sigma[i]
        P[off["ghat_ref"], i] = c.ghat_ref[i]
        P[off["b0"], i] = fo.b0
        P[off["d"], i] = fo.d
        P[off["abar"], i] = o.alpha1_bar[i]
        if sat:
            P[off["u_max"], i] = c.u_max[i]
    return P


def expressions(sc: Scenario) -> dict[str, Expr]:
    """Every expression of t the closed loop evaluates, by its parameter name.

    Parameters
    ----------
    sc : Scenario
    """
    out: dict[str, Expr] = {}
    if sc.leader.u0 is not None:
        out.update({f"expr:leader.u0[{k}]": e for k, e in enumerate(sc.leader.u0)})
    for i, fo in enumerate(sc.followers):
        out[f"expr:followers[{i}].g"] = fo.g.expr
        out.update({f"expr:followers[{i}].f[{r}]": e for r, e in enumerate(fo.f)})
    return out


def graph_weights(adjacency: Any, pinning: Any, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``L_Bᵀ`` and ``(a0 ∘ h)ᵀ`` of one graph (dense).

    Parameters
    ----------
    adjacency : ndarray
        N×N, a_ij.
    pinning : ndarray
        N, a_i0.
    h : ndarray
        The gauge signs (from the certified gains).
    """
    A = np.asarray(adjacency, dtype=float)
    a0 = np.asarray(pinning, dtype=float)
    return pinned_laplacian(A, a0).toarray().T, (a0 * h).reshape(1, -1)


def graph_pattern(sc: Scenario, dense: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Where ``L_Bᵀ`` and ``(a0 ∘ h)ᵀ`` can be nonzero over every topology the run reaches.

    Parameters
    ----------
    sc : Scenario
    dense : bool
        The graph as data: every entry.
    """
    N = sc.N
    if dense:
        return np.ones((N, N), bool), np.ones((1, N), bool)
    L, a = np.zeros((N, N), bool), np.zeros((1, N), bool)
    for top in sc.graph.topologies():
        LBt, a0h = graph_weights(top.adjacency, top.pinning, np.ones(N))
        L |= LBt != 0
        a |= a0h != 0
    return L, a


def topology_count(sc: Scenario, dense: bool = False) -> int:
    """Topologies the code holds: the graph's, at least :data:`DENSE_TOPOLOGIES` when dense.

    Parameters
    ----------
    sc : Scenario
    dense : bool
        The graph as data.
    """
    K = len(sc.graph.topologies())
    return max(K, DENSE_TOPOLOGIES) if dense else K


def graph_values(
    sc: Scenario, h: np.ndarray, adjacency: Any, pinning: Any, dense: bool = False
) -> np.ndarray:
    """The ``graph`` weights of one topology on ``sc``'s pattern (:func:`graph_pattern`).

    A link of the pattern that the topology lacks gets weight 0 (a cut link); a link
    outside the pattern is refused (it would need other code).

    Parameters
    ----------
    sc : Scenario
        Fixes the pattern.
    h : ndarray
        Gauge signs.
    adjacency, pinning : ndarray
        The topology.
    dense : bool
        The graph as data (every entry).

    Raises
    ------
    ScenarioError
        If the topology has a link outside the pattern.
    """
    L, a = graph_pattern(sc, dense)
    LBt, a0h = graph_weights(adjacency, pinning, h)
    if np.any(LBt[~L] != 0) or np.any(a0h[~a] != 0):
        raise ScenarioError(
            sc.path, "graph", "a link outside the compiled graph's pattern", "a link of the graph"
        )
    return np.concatenate([LBt.T[L.T], a0h.T[a.T]])  # CasADi's column-major nonzeros


def nonzeros_count(sc: Scenario, dense: bool = False) -> int:
    """Weights per topology in the ``graph`` block.

    Parameters
    ----------
    sc : Scenario
    dense : bool
        The graph as data.
    """
    L, a = graph_pattern(sc, dense)
    return int(L.sum() + a.sum())


def layout_of(sc: Scenario, dense: bool = False) -> ParamLayout:
    """The parameter layout of ``sc`` (sizes only: equal for equal structures).

    ``graph`` holds the weights of every topology in turn, ``graph_times`` the
    switching times between them and ``graph_fade`` the fade's duration
    (:func:`symbolic.closed_loop.graph_coupling`); with the graph as data, ``v1`` V1's
    coefficients of the graph (z, l̄, k1).

    Parameters
    ----------
    sc : Scenario
    dense : bool
        The graph as data (:mod:`symbolic.parameters`).
    """
    _, npar = param_layout(sc.n, sc.controller.u_max is not None)
    K = topology_count(sc, dense)
    sizes = [("agents", npar * sc.N), ("graph", K * nonzeros_count(sc, dense))]
    sizes += [("graph_times", K - 1), ("graph_fade", 1 if K > 1 else 0)]
    sizes += [("v1", 2 * sc.N + 1)] if dense else []
    sizes += [(k, len(e.literals())) for k, e in expressions(sc).items()]
    slices, k = {}, 0
    for name, size in sizes:
        slices[name] = slice(k, k + size)
        k += size
    return ParamLayout(slices, k, dense)


def param_values(sc: Scenario, gains: Gains, dense: bool = False) -> np.ndarray:
    """The parameter vector p of ``sc`` (layout :func:`layout_of`).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
        Supplies the gauge h of signed graphs (with the graph as data, also V1's z, l̄, k1).
    dense : bool
        The graph as data: every entry's weight, the last topology repeated from t = ∞ up to
        :func:`topology_count` (its jump is 0: the same weights at every t).
    """
    lay = layout_of(sc, dense)
    p = np.zeros(lay.size)
    p[lay.slices["agents"]] = param_matrix(sc).ravel(order="F")  # agent-major
    h = np.diag(np.atleast_2d(gains.H)).astype(float)
    tops = sc.graph.topologies()
    vals = [graph_values(sc, h, top.adjacency, top.pinning, dense) for top in tops]
    pad = topology_count(sc, dense) - len(tops)
    p[lay.slices["graph"]] = np.concatenate(vals + vals[-1:] * pad)
    p[lay.slices["graph_times"]] = [top.t_start for top in tops[1:]] + [np.inf] * pad
    p[lay.slices["graph_fade"]] = [sc.graph.link_fade] if len(tops) + pad > 1 else []
    if dense:
        p[lay.slices["v1"]] = v1_coefficients(sc, gains)
    for name, e in expressions(sc).items():
        p[lay.slices[name]] = e.literals()
    return p


def v1_coefficients(sc: Scenario, gains: Gains) -> np.ndarray:
    """V1's numbers that depend on the graph (eq. (17)): Lemma 3's z, the diagonal l̄ of
    L̄ = H(L + B)H and k1, as the ``v1`` block of p.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    """
    z = np.diag(np.atleast_2d(gains.Z))
    lbar = graph_matrices(sc.graph, gains).l_bar  # checks L̄ against the graph
    return np.concatenate([z, lbar, [float(gains.k1)]])


# ----------------------------------------------------------------------------- structure
def _plain(v: Any) -> Any:
    """A JSON-able form of a setting's value (arrays as nested lists)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, tuple | list):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in sorted(v.items())}
    return v


def _section(obj: Any, skip: tuple[str, ...]) -> dict[str, Any]:
    return {f.name: _plain(getattr(obj, f.name)) for f in fields(obj) if f.name not in skip}


def structure(sc: Scenario, gains: Gains, dense: bool = False) -> dict[str, Any]:
    """Everything of ``sc`` and ``gains`` that is written into the generated code.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    dense : bool
        The graph as data: of the graph only N and the topologies held, of the gains
        not those that depend on the graph (:data:`_GRAPH_GAINS`).
    """
    L = sc.leader
    trace = None if L.u0_trace is None else hashlib.sha256(L.u0_trace.tobytes()).hexdigest()
    return {
        "leader": {
            "A0": _plain(L.A0),
            "B0": _plain(L.B0),
            "C0": _plain(L.C0),
            "u0": None if L.u0 is None else [e.template() for e in L.u0],
            "u0_trace": trace,
            "u0_hold": L.u0_hold,  # a held trace is other code than an interpolated one
            # a held trace's shaped jumps are written into the code (core/hold.py)
            **({"u0_rise": L.u0_rise} if L.u0_hold and L.u0_rise > 0 else {}),
        },
        "graph": {
            "pattern": "dense" if dense else [m.astype(int).tolist() for m in graph_pattern(sc)],
            "topologies": topology_count(sc, dense),
        },
        "followers": [
            {
                "model": fo.model,
                "params": _plain(fo.params),
                "g": fo.g.expr.template(),
                "f": [e.template() for e in fo.f],
            }
            for fo in sc.followers
        ],
        "observer": _section(sc.observer, _OBSERVER_PARAMS),
        "controller": {
            **_section(sc.controller, _CONTROLLER_PARAMS),
            "saturated": sc.controller.u_max is not None,
        },
        "options": _section(sc.options, ()),
        "gains": _section(gains, ("certificate", "info", *(_GRAPH_GAINS if dense else ()))),
    }


def structure_key(sc: Scenario, gains: Gains, dense: bool = False) -> str:
    """SHA-256 of :func:`structure`: equal keys, equal generated code.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    dense : bool
        The graph as data.
    """
    text = json.dumps(structure(sc, gains, dense), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


# ----------------------------------------------------------------------------- per-agent rows
@dataclass(frozen=True)
class RowLayout:
    """The columns of one follower's row of runtime numbers in the per-agent engine.

    The per-agent kernels (:func:`symbolic.cascade.agent_block`) read every number a
    scenario may vary without changing a model's equations from their agent's row: the
    per-agent numbers of :func:`param_layout` (columns ``0..npar``), the observer's gains
    (:func:`symbolic.observer.gain_values`) and the literals of the leader's u0
    expressions (both the same in every row: each block evaluates them) and,
    per fault component (g_i, then f_i1 … f_in), the index of the follower's template
    among the scenario's distinct templates of that component and one literal slot per
    template (only the chosen template's slot is filled). What the kernels compile in is
    then only the templates (:meth:`key`), never their numbers.

    Attributes
    ----------
    npar : int
        Per-agent numbers (:func:`param_layout`) at the row's start.
    gains : slice
        The observer's gains (columns ``npar..``; empty without gains).
    gain_pattern : tuple
        Where the observer's gain matrices are nonzero (:func:`symbolic.observer.gain_pattern`).
    u0 : tuple of slice
        The literals of u0_k (``expr:leader.u0[k]``).
    select : tuple of int
        Per fault component, the column of the follower's template index.
    slots : tuple of tuple of slice
        Per fault component, per template, the columns of its literals.
    templates : tuple of tuple of Expr
        Per fault component, one expression of each distinct template (sorted by template).
    size : int
        Columns of a row.
    """

    npar: int
    gains: slice
    gain_pattern: tuple
    u0: tuple[slice, ...]
    select: tuple[int, ...]
    slots: tuple[tuple[slice, ...], ...]
    templates: tuple[tuple[Expr, ...], ...]
    size: int

    def key(self) -> dict[str, Any]:
        """What the kernels compile in of this layout: sizes, patterns, templates, no number."""
        return {
            "npar": self.npar,
            "gains": [self.gains.stop - self.gains.start, _plain(self.gain_pattern)],
            "u0": [sl.stop - sl.start for sl in self.u0],
            "faults": [[e.template() for e in tpl] for tpl in self.templates],
        }


def _components(sc: Scenario, i: int) -> list[Expr]:
    """Follower i's fault components: g_i, then f_i1 … f_in."""
    fo = sc.followers[i]
    return [fo.g.expr, *fo.f]


def row_layout(sc: Scenario, og: ObserverGains | None = None) -> RowLayout:
    """The per-agent row layout of ``sc`` (:class:`RowLayout`).

    Parameters
    ----------
    sc : Scenario
    og : ObserverGains, optional
        The observer's gains (their count and patterns; default: no gain columns).
    """
    _, npar = param_layout(sc.n, sc.controller.u_max is not None)
    ng = 0 if og is None else gain_values(og).size
    gains = slice(npar, npar + ng)
    pattern = () if og is None else tuple(tuple(p) for p in gain_pattern(og))
    k = npar + ng
    u0 = []
    for e in sc.leader.u0 or ():
        u0.append(slice(k, k + len(e.literals())))
        k += len(e.literals())
    select, slots, templates = [], [], []
    for c in range(1 + sc.n):
        distinct: dict[str, Expr] = {}
        for i in range(sc.N):
            e = _components(sc, i)[c]
            distinct.setdefault(e.template(), e)
        tpl = tuple(distinct[name] for name in sorted(distinct))
        select.append(k)
        k += 1
        sl = []
        for e in tpl:
            sl.append(slice(k, k + len(e.literals())))
            k += len(e.literals())
        slots.append(tuple(sl))
        templates.append(tpl)
    return RowLayout(
        npar, gains, pattern, tuple(u0), tuple(select), tuple(slots), tuple(templates), k
    )


def row_slices(sc: Scenario, lay: RowLayout) -> dict[str, tuple[int | None, slice]]:
    """Where each expression's literals are in the rows, by its name in p (:func:`expressions`).

    Parameters
    ----------
    sc : Scenario
    lay : RowLayout
        :func:`row_layout` of ``sc``.

    Returns
    -------
    dict
        ``"expr:leader.u0[k]"`` -> (None, columns): every row holds them;
        ``"expr:followers[i].g"``, ``"expr:followers[i].f[r]"`` -> (i, columns).
    """
    out: dict[str, tuple[int | None, slice]] = {
        f"expr:leader.u0[{k}]": (None, sl) for k, sl in enumerate(lay.u0)
    }
    names = ["g", *(f"f[{r}]" for r in range(sc.n))]
    for i in range(sc.N):
        for c, e in enumerate(_components(sc, i)):
            pick = [t.template() for t in lay.templates[c]].index(e.template())
            out[f"expr:followers[{i}].{names[c]}"] = (i, lay.slots[c][pick])
    return out


def agent_rows(
    sc: Scenario, og: ObserverGains | None = None, lay: RowLayout | None = None
) -> np.ndarray:
    """Every follower's row of runtime numbers (N × ``lay.size``, :class:`RowLayout`).

    Parameters
    ----------
    sc : Scenario
    og : ObserverGains, optional
        The observer's gains (:func:`symbolic.observer.gain_values`).
    lay : RowLayout, optional
        Default :func:`row_layout` of ``sc`` and ``og``; another layout must hold
        ``sc``'s templates and ``og``'s gain patterns.

    Raises
    ------
    ScenarioError
        If ``sc`` has a fault expression whose template ``lay`` lacks, or gains on other
        patterns.
    """
    lay = lay or row_layout(sc, og)
    R = np.zeros((sc.N, lay.size))
    R[:, : lay.npar] = param_matrix(sc).T
    if og is not None:
        if tuple(tuple(p) for p in gain_pattern(og)) != lay.gain_pattern:
            raise ScenarioError(
                sc.path,
                "gains",
                "observer gains with other zeros than the compiled kernels'",
                "kernels built for these gains",
            )
        R[:, lay.gains] = gain_values(og)
    for sl, e in zip(lay.u0, sc.leader.u0 or (), strict=True):
        R[:, sl] = e.literals()
    for i in range(sc.N):
        for c, e in enumerate(_components(sc, i)):
            names = [t.template() for t in lay.templates[c]]
            if e.template() not in names:
                raise ScenarioError(
                    sc.path,
                    f"followers[{i + 1}]",
                    f"fault expression {e.text!r} has a form the compiled kernels lack",
                    "kernels built for this scenario",
                )
            pick = names.index(e.template())
            R[i, lay.select[c]] = pick
            R[i, lay.slots[c][pick]] = e.literals()
    return R
