"""The registry of claims: every row of the bound-vs-actual table names one of these.

A claim is data: an id, its text, the kind a failure has (:class:`Kind`) and what its
derivation depends on (:class:`Dep`). The table's rules read the registry, never the
text: the saturation rule demotes the rows whose claim depends on
:attr:`Dep.SATURATION`, the switching rule those that depend on
:attr:`Dep.BASE_GRAPH`; health switches and operator steps restart the claims that
depend on :attr:`Dep.HEALTH` and :attr:`Dep.OPERATOR_STEPS` on intervals
(:mod:`verify.intervals`). A new check is one :func:`register` call and the function
that adds its rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Kind(StrEnum):
    """What a failure of a row means (docs/verification.md, 'Kinds of rows')."""

    GUARANTEED = "guaranteed"  # follows from the theory: a failure is a bug
    CONSISTENCY = "consistency"  # cannot fail for a correct implementation: a bug
    PAPER = "paper"  # the paper's own claim where it does not follow as printed
    INFO = "info"  # a measurement with no pass/fail


#: kinds whose failure is a bug (``check`` exits 1 without ``--strict``)
BUG_KINDS = (Kind.GUARANTEED.value, Kind.CONSISTENCY.value)


class Dep(StrEnum):
    """What a claim's derivation depends on."""

    HEALTH = "health"  # g_i: restarted at its switches, a ramp's rate in the constants
    SWITCHING = "switching"  # restarted at a switch of the follower's neighbourhood
    BASE_GRAPH = "base graph"  # V1 of the base graph or V2 from t = 0: void after a switch
    SATURATION = "saturation"  # the unsaturated law u = ĝΨ (29)
    DERIVATIVES = "derivatives variant"  # the oracle derivatives (exact feedforward)
    OPERATOR_STEPS = "operator steps"  # restarted where u0 jumps (pinned followers)


@dataclass(frozen=True)
class Claim:
    """One claim of the table.

    Attributes
    ----------
    id : str
        Stable identifier (the ``claim_id`` column of bounds.csv).
    text : str
        The ``claim`` column; ``{}`` fields are filled by the row (:meth:`render`).
    kind : Kind
        The kind when every condition of its derivation holds.
    depends : frozenset of Dep
        What the derivation depends on.
    """

    id: str
    text: str
    kind: Kind
    depends: frozenset[Dep] = frozenset()

    def render(self, **fields: object) -> str:
        """The claim's text with its fields filled.

        Parameters
        ----------
        **fields : object
            Values for the ``{name}`` fields of the text (none: the text as registered).
        """
        return self.text.format(**fields) if fields else self.text


REGISTRY: dict[str, Claim] = {}
_BY_TEXT: dict[str, Claim] = {}


def register(cid: str, text: str, kind: Kind, *depends: Dep) -> Claim:
    """Add a claim to the registry and return it.

    Parameters
    ----------
    cid : str
        Unique id.
    text : str
        The claim's text (``{name}`` fields allowed).
    kind : Kind
        Its kind when its derivation applies.
    *depends : Dep
        What the derivation depends on.
    """
    if cid in REGISTRY:
        raise ValueError(f"claim {cid!r} registered twice")
    c = Claim(cid, text, Kind(kind), frozenset(depends))
    REGISTRY[cid] = c
    _BY_TEXT[text] = c
    return c


def get(cid: str) -> Claim:
    """The claim with id ``cid`` (KeyError naming the known ids when there is none).

    Parameters
    ----------
    cid : str
        The claim's registered id.
    """
    try:
        return REGISTRY[cid]
    except KeyError:
        raise KeyError(f"no claim {cid!r}; registered: {', '.join(REGISTRY)}") from None


def depends(cid: str, dep: Dep) -> bool:
    """Whether claim ``cid`` depends on ``dep`` (False for an unknown id).

    Parameters
    ----------
    cid : str
        The claim's registered id.
    dep : Dep
        The dependency to look for.
    """
    c = REGISTRY.get(cid)
    return c is not None and dep in c.depends


H, SW, BG, SAT, DER, STEP = (
    Dep.HEALTH,
    Dep.SWITCHING,
    Dep.BASE_GRAPH,
    Dep.SATURATION,
    Dep.DERIVATIVES,
    Dep.OPERATOR_STEPS,
)
G, C, P, I = Kind.GUARANTEED, Kind.CONSISTENCY, Kind.PAPER, Kind.INFO

# Theorem 1 (observer)
T1_RATE = register("t1.decay_rate", "T1 |ebar_eta_i| decay rate >= delta~/2 (fit on tail)", I, BG)
T1_ENTER = register("t1.enter", "T1 time |ebar_eta_i| enters {level:g}", I)
T1_TAIL = register("t1.tail", "T1 |ebar_eta_i| -> 0 (tail sup)", I)
T1_SUPPORTED = register(
    "t1.dv1.supported", "T1 dV1/dt <= -delta~ V1, supported rate (fraction of time)", G, BG
)
T1_PRINTED = register(
    "t1.dv1.printed", "T1 dV1/dt <= -delta~ V1, printed rate (fraction of time)", P, BG
)
T1_FLOOR = register(
    "t1.dv1.floor", "T1 dV1/dt <= -delta~ V1 + c_phi, phi floor (fraction of time)", G, BG
)
# Theorem 2 (controller), the paper's constants
T2_CHI_PAPER = register("t2.chi.paper", "T2 |chi_si| <= chi_bar_si (31), paper", P, SAT)
T2_E_PAPER = register("t2.e.paper", "T2 |e_ti,r| <= chi_bar/lambda_ir (31), paper", P, SAT)
LEMMA2_PAPER = register("lemma2.paper", "Lemma 2 |de_ti,r/dt| <= 2 chi_bar, paper", P, SAT)
LEMMA1_PAPER = register(
    "lemma1.paper",
    "Lemma 1 reaching time t_f (V2 enters chi_v/(Omega(1-delta))), paper",
    P,
    SAT,
    BG,
)
T2_CONSISTENCY = register(
    "t2.eq38",
    "consistency: (38) dV2/dt <= -chi'K chi - k2|th-d|^2/2 + k2|d|^2/2 (+slack) (fraction)",
    C,
    SAT,
    DER,
    H,
)
# Theorem 2, the provable variant, restarted on intervals
T2_CHI = register(
    "t2.chi.provable", "T2 |chi_si| <= chi_bar_si, provable variant", G, SAT, DER, H, SW, STEP
)
T2_E = register(
    "t2.e.provable",
    "T2 |e_ti,r| <= max(chi_bar/lambda_ir, |e_ti,r(t_s)|), provable variant",
    G,
    SAT,
    DER,
    H,
    SW,
    STEP,
)
T2_CHI_ENV = register(
    "t2.chi.envelope",
    "T2 |chi_si(t)| <= sqrt(2 W(t)/lambda_min(M)), comparison-lemma envelope from V2(t_s) "
    "(pointwise)",
    G,
    SAT,
    DER,
    H,
    SW,
    STEP,
)
# Definition 1 (formation tracking)
DEF1_PAPER = register("def1.paper", "Def. 1 limsup |p_i - h_i y0 - b_i| <= chi_bar, paper", P, SAT)
DEF1_DERIVED = register(
    "def1.derived",
    "Def. 1 |p_i - h_i y0 - b_i| <= derived bound (pointwise)",
    G,
    SAT,
    DER,
    H,
    SW,
    STEP,
    BG,
)
DEF1_ENV = register(
    "def1.envelope",
    "Def. 1 |p_i - h_i y0 - b_i| <= envelope bound from V2(t_s) (pointwise)",
    G,
    SAT,
    DER,
    H,
    SW,
    STEP,
    BG,
)
FORMATION = register("formation.leader", "Formation |p_i - h_i y0 - R(tau_i^0) b_i0| (tail sup)", I)
# Fig. 13 (ablation)
FIG13_VERDICT = register(
    "fig13.verdict",
    "Fig. 13: time |e_ti| enters {factor:g} x max tail sup: ablation (42) vs FTC (29)",
    P,
)
FIG13_FIXED = register(
    "fig13.fixed",
    "Fig. 13: time |e_ti| enters {level:g} (fixed level): ablation (42) vs FTC (29)",
    I,
)
FIG13_RATE = register(
    "fig13.rate", "Fig. 13: decay rate of |e_ti| (fit): ablation (42) vs FTC (29)", I
)
FIG13_TAIL = register("fig13.tail", "Fig. 13: tail sup |e_ti|: ablation (42) vs FTC (29)", I)

#: the claims of a follower's tracking guarantee at its ultimate level (after t_c)
TRACKING = frozenset({T2_CHI.id, T2_E.id, DEF1_DERIVED.id})
#: the claims that bound the transient of each interval from its start (comparison lemma)
ENVELOPE = frozenset({T2_CHI_ENV.id, DEF1_ENV.id})
