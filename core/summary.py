"""A human-readable summary of a loaded scenario (``python -m symbolic summary SCENARIO``).

The summary derives every follower model used (so Property 1/2 are checked and
the inertia bounds of Theorem 2 are printed) but runs nothing else.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.errors import ScenarioError
from core.expression_tree import Node
from core.faults import node_text
from core.models import REGISTRY, ELModel, build_model
from core.scenario import Follower, Scenario


def _num(x: float) -> str:
    return f"{float(x):.6g}"


def _mat(a: np.ndarray) -> str:
    a = np.atleast_2d(a)
    return "[" + ", ".join("[" + ", ".join(_num(x) for x in row) + "]" for row in a) + "]"


def _vec(a: Sequence[float] | np.ndarray) -> str:
    return "(" + ", ".join(_num(x) for x in np.ravel(a)) + ")"


def _per_agent(a: np.ndarray) -> str:
    """One value if all agents share it, else the list (1-based agents, rows for N×n)."""
    a = np.asarray(a, dtype=float)
    if a.size and np.all(a == a.flat[0]):
        return f"{_num(a.flat[0])} (all)"
    if a.ndim == 1:
        return _vec(a)
    return "; ".join(f"{i + 1}: {_vec(r)}" for i, r in enumerate(a))


def _gain(v: object) -> str:
    if v is None:
        return "synthesize"
    if isinstance(v, np.ndarray):
        return _mat(v) + " (given)"
    return f"{_num(v)} (given)"  # type: ignore[arg-type]


def _models(scn: Scenario) -> dict[tuple[str, tuple], ELModel]:
    """Build each distinct (model, params) once; a failed property names the follower."""
    out: dict[tuple[str, tuple], ELModel] = {}
    for i, fo in enumerate(scn.followers):
        k = (fo.model, tuple(sorted(fo.params.items())))
        if k in out:
            continue
        try:
            out[k] = build_model(fo.model, fo.params)
        except ScenarioError as exc:
            raise ScenarioError(
                scn.path, f"followers[{i + 1}].params", exc.problem, exc.expected
            ) from None
    return out


def summarize(scenario: Scenario) -> str:
    """Multi-line text describing ``scenario``.

    Lists N, n, m, p, the graph's edges and pinned followers, every follower
    (model, M bounds, g_i, f_i, d_i, p_i(0), b_i0), which gains are given and
    which are synthesised, the controller options, the initial estimator
    states and the integration settings.

    Parameters
    ----------
    scenario : Scenario
        A loaded scenario (:func:`core.scenario.load_scenario`).

    Returns
    -------
    str
        The summary, ending with a newline.

    Raises
    ------
    ScenarioError
        If a follower model fails Property 1 or 2 with its parameters.
    """
    models = _models(scenario)
    parts = (
        _header_lines(scenario),
        _leader_lines(scenario),
        _graph_lines(scenario),
        _model_lines(scenario, models),
        _follower_lines(scenario),
        _gain_lines(scenario),
        _option_lines(scenario),
        _run_lines(scenario),
    )
    return "\n".join(line for part in parts for line in part) + "\n"


def _header_lines(s: Scenario) -> list[str]:
    lines = [f"scenario     {s.name}  ({s.path}, sha256 {s.sha256[:12]})"]
    if s.description:
        lines.append(f"             {s.description}")
    lines.append(
        f"dimensions   N = {s.N} followers, n = {s.n} coordinates each, "
        f"m = {s.m} leader states, p = {s.p} operator inputs"
    )
    return lines


def _leader_lines(s: Scenario) -> list[str]:
    """The leader, eq. (3)."""
    L = s.leader
    lines = [
        f"leader       A0 = {_mat(L.A0)}, B0 = {_mat(L.B0)}, C0 = {_mat(L.C0)}",
        f"             eta0(0) = {_vec(L.eta0)}, alpha = {_num(L.alpha)} (bound on ||u0||)",
    ]
    if L.u0 is not None:
        lines.append("             u0(t) = [" + ", ".join(e.text for e in L.u0) + "]")
    else:
        tr = L.u0_trace
        assert tr is not None
        lines.append(
            f"             u0(t) from a CSV trace: {len(tr)} rows on "
            f"[{_num(tr[0, 0])}, {_num(tr[-1, 0])}] s, "
            + ("held from each row to the next" if L.u0_hold else "linear between rows")
        )
    return lines


def _graph_lines(s: Scenario) -> list[str]:
    """Edges and pinned followers (section 1); ``adjacency[i, j] = a_ij``: i hears j."""
    A, pin = s.graph.adjacency, s.graph.pinning
    edges = [
        f"{j + 1}->{i + 1}" + ("" if A[i, j] == 1 else f" ({_num(A[i, j])})")
        for i in range(s.N)
        for j in range(s.N)
        if A[i, j] != 0
    ]
    pinned = [
        f"{i + 1}" + ("" if pin[i] == 1 else f" ({_num(pin[i])})") for i in range(s.N) if pin[i] > 0
    ]
    kind = "signed (antagonistic edges present)" if s.graph.signed else "cooperative"
    return [
        f"graph        {kind}; edges j->i (i hears j, weight if not 1): "
        + (", ".join(edges) or "none"),
        "             pinned (hear the leader, a_i0): " + ", ".join(pinned),
    ] + _switch_lines(s)


def _switch_lines(s: Scenario) -> list[str]:
    """The ``[[graph.switches]]``, one line per switching time (none without switches)."""
    lines = []
    for top in s.graph.topologies()[1:]:
        links = ", ".join(
            f"{sw.link} = {_num(sw.weight)}" for sw in s.graph.switches if sw.time == top.t_start
        )
        lines.append(f"             from t = {_num(top.t_start)} s: {links}")
    return lines


def _model_lines(s: Scenario, models: dict[tuple[str, tuple], ELModel]) -> list[str]:
    """Each distinct follower model, eq. (2): its users, parameters and M bounds."""
    lines = ["models"]
    for (name, items), mdl in models.items():
        users = [
            str(i + 1)
            for i, fo in enumerate(s.followers)
            if (fo.model, tuple(sorted(fo.params.items()))) == (name, items)
        ]
        prm = ", ".join(f"{k} = {_num(v)}" for k, v in items)
        lo, hi = mdl.M_bounds
        lines += [
            f"  {name} (followers {', '.join(users)}): {REGISTRY[name].description}",
            f"      params: {prm or 'none'}",
            f"      M bounds: lambda_min >= {lo:.4f}, lambda_max <= {hi:.4f}; "
            f"Property 1 {mdl.checks.get('property1', '?')}, "
            f"Property 2 {mdl.checks.get('property2', '?')}",
        ]
    return lines


def _follower_lines(s: Scenario) -> list[str]:
    lines = ["followers"]
    for i, fo in enumerate(s.followers):
        lines += [
            f"  {i + 1}: {fo.model}, p(0) = {_vec(fo.p0)}, q(0) = {_vec(fo.q0)}, b0 = {_vec(fo.b0)}",
            f"     g(t) = {_health_text(fo, s.options.fault_slots)} (min {_num(fo.g.minimum)})",
            f"     f(t) = [{', '.join(_bias_texts(fo, s.options.fault_slots))}], "
            f"|f_r| <= d = {_vec(fo.d)}",
        ]
        lines += [f"     fault {k + 1}: {fa.describe()}" for k, fa in enumerate(fo.faults)]
    return lines


def _health_text(fo: Follower, slots: int | None = None) -> str:
    """g_i as written (the file's g, times the faults listed below), with its switching times."""
    e = fo.g.expr
    lost = any(not fa.is_bias for fa in fo.faults)
    if slots:  # e = g_file * product of the generic form's slots (options.fault_slots)
        g = _text(e.node.left) + (" x the faults below" if lost else "")
        g += f" (generic form, {slots} fault slots)"
    elif lost:  # e = g_file * product of fault factors
        g = f"{_text(e.node.left)} x the faults below"
    else:
        g = e.text if not e.is_constant() else _num(fo.g.minimum)
    if fo.g.breakpoints:
        times = [_num(b) for b in fo.g.breakpoints]
        shown = ", ".join(times[:8]) + (f", ... ({len(times)} in all)" if len(times) > 8 else "")
        g += f"  [faults at t = {shown}]"
    return g


def _bias_texts(fo: Follower, slots: int | None = None) -> list[str]:
    """f_ir as written in the file, plus the bias faults listed below."""
    biased = any(fa.is_bias for fa in fo.faults)
    if slots and not biased:  # e = f_file + the generic form's slots, each adding 0
        return [_text(e.node.left) for e in fo.f]
    if not biased:
        return [e.text for e in fo.f]
    return [f"{_text(e.node.left)} + biases below" for e in fo.f]


def _text(node: Node) -> str:
    """A node's text without the outer parentheses the fault composition adds."""
    text = node_text(node)
    return text[1:-1] if text.startswith("(") and text.endswith(")") else text


def _gain_lines(s: Scenario) -> list[str]:
    """Gains, given or synthesised: eqs. (9), (15), (16), (29), (30)."""
    O, C = s.observer, s.controller
    return [
        f"observer     lambda1 = {_gain(O.lambda1)}, lambda2 = {_gain(O.lambda2)}, "
        f"Q = {_gain(O.Q)}, Theta = {_gain(O.Theta)}",
        f"             alpha1 = {_per_agent(O.alpha1)}, alpha1_bar = {_per_agent(O.alpha1_bar)}, "
        f"phi(0) = {_per_agent(O.phi0)}, phi_min = {_num(O.phi_min)}",
        f"             LMI (15): lambda_bar1 = {_num(O.lambda_bar1)}, delta1 = {_num(O.delta1)}, "
        f"delta1_hat = {_num(O.delta1_hat)}; LMI (16): delta2 = {_num(O.delta2)}, "
        f"delta2_hat = {_num(O.delta2_hat)}; margin = {_num(O.margin)}",
        f"controller   Lambda = {_per_agent(C.Lambda)}, k1 = {_per_agent(C.k1)}, "
        f"k2 = {_per_agent(C.k2)} (all given)",
        f"             gamma = {_per_agent(C.gamma)}, sigma = {_per_agent(C.sigma)}, "
        f"ghat_ref = {_per_agent(C.ghat_ref)}, g_min = {_num(C.g_min)}",
    ]


def _option_lines(s: Scenario) -> list[str]:
    Op = s.options
    sign = Op.sign if Op.sign == "exact" else f"{Op.sign} (width {_num(Op.sign_width)})"
    deriv = Op.derivatives
    if deriv == "filtered":
        deriv += f" (bandwidth {_num(Op.filter_bandwidth)} rad/s)"
    return [
        f"options      sign = {sign}, ghat law = {Op.ghat_law}, "
        f"feedforward = {'on' if Op.feedforward else 'off (eq. (29) as printed)'}, "
        f"ablation (42) = {'on' if Op.ablation else 'off'}",
        f"             derivatives = {deriv}, tau threshold = {_num(Op.tau_threshold)}"
        + ("" if Op.fault_slots is None else f", fault slots = {Op.fault_slots}"),
    ]


def _run_lines(s: Scenario) -> list[str]:
    """Initial estimator states, integration settings and breakpoints."""
    In, I = s.initial, s.integration
    bps = s.breakpoints()
    return [
        f"initial      eta = {_per_agent(In.eta)}, mu = {_per_agent(In.mu)}, "
        f"theta_hat = {_per_agent(In.theta_hat)}, ghat = {_per_agent(In.ghat)}, "
        f"start = {In.start}",
        f"integration  {I.method}, rtol = {_num(I.rtol)}, atol = {_num(I.atol)}, "
        f"horizon = {_num(I.horizon)} s, output step = {_num(I.output_step)} s, "
        f"fixed step = {_num(I.fixed_step)} s, max steps = {I.max_steps}",
        "breakpoints  " + (", ".join(_num(b) for b in bps) if bps else "none"),
    ]
