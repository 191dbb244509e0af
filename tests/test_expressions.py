"""The whitelist expression parser (core/expressions.py)."""

from __future__ import annotations

import inspect
import math
import pickle
import re
import typing

import casadi as ca
import numpy as np
import pytest
from helpers import PACKAGES, ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import ExpressionError, ToolkitError
from core.expression_tree import METHODS, BinOp, Call, Neg, Node, Num, Time, Visitor, visit
from core.expressions import FUNCTIONS, parse_expression

WHERE = "scn.toml: followers[2].f[0]"

# The paper's expressions (Table 2) and their plain-Python meaning.
PAPER = {
    "2*cos(t)": lambda t: 2 * math.cos(t),
    "4*sin(2*t) + 1": lambda t: 4 * math.sin(2 * t) + 1,
    "3*cos(t) + exp(-2*t)": lambda t: 3 * math.cos(t) + math.exp(-2 * t),
    "2*sin(t)": lambda t: 2 * math.sin(t),
    "4*cos(t)": lambda t: 4 * math.cos(t),
    "0.95": lambda t: 0.95,
}

# Every whitelisted function, with an independent reference.
OTHERS = {
    "tan(t/4) - sqrt(t + 1) + log(t + 2)": lambda t: (
        math.tan(t / 4) - math.sqrt(t + 1) + math.log(t + 2)
    ),
    "abs(sin(t)) * tanh(t - 1) ** 2": lambda t: abs(math.sin(t)) * math.tanh(t - 1) ** 2,
    "atan2(sin(t), cos(t) + 2) + pi": lambda t: math.atan2(math.sin(t), math.cos(t) + 2) + math.pi,
    "min(t, 2) - max(1, t/2)": lambda t: min(t, 2) - max(1, t / 2),
    "1 - 0.4*step(t - 5)": lambda t: 1 - 0.4 * (1.0 if t >= 5 else 0.0),
    "sat(2*(t - 3)) / -2 + +t": lambda t: max(-1.0, min(1.0, 2 * (t - 3))) / -2 + t,
    "2**-t": lambda t: 2.0**-t,
}

TIMES = [0.0, 0.3, 1.0, 2.5, 4.999, 5.0, 7.1, 19.9]


def _casadi_value(e, t: float) -> float:
    ts = ca.SX.sym("t")
    f = ca.Function("f", [ts], [e.casadi(ts)])
    return float(f(t))


@pytest.mark.parametrize("text", list(PAPER) + list(OTHERS))
def test_accepts_and_backends_agree_with_python(text):
    ref = {**PAPER, **OTHERS}[text]
    e = parse_expression(text, where=WHERE)
    for t in TIMES:
        want = ref(t)
        assert float(e.numpy(t)) == pytest.approx(want, rel=1e-12, abs=1e-12)
        assert _casadi_value(e, t) == pytest.approx(want, rel=1e-12, abs=1e-12)
    # vectorised numpy evaluation equals the pointwise one
    arr = e.numpy(np.array(TIMES))
    assert np.broadcast_to(arr, (len(TIMES),)) == pytest.approx([ref(t) for t in TIMES])


def test_numbers_are_constants():
    e = parse_expression(0.95, where=WHERE)
    assert e.is_constant() and float(e.numpy(3.0)) == 0.95
    assert not parse_expression("t", where=WHERE).is_constant()
    assert parse_expression("2*pi", where=WHERE).is_constant()


def test_breakpoints_of_steps():
    e = parse_expression("1 - 0.3*step(t - 5) - 0.2*step(2*t - 24) + sat(t - 3)", where=WHERE)
    assert e.breakpoints() == pytest.approx((2.0, 4.0, 5.0, 12.0))  # sat kinks at t - 3 = ±1
    e2 = parse_expression("abs(t - 3)", where=WHERE)
    assert e2.breakpoints() == pytest.approx((3.0,))
    assert parse_expression("step(sin(t))", where=WHERE).breakpoints() == ()  # not affine


REJECTED = [
    ("__import__('os')", "__import__"),
    ("__import__('os').system('true')", ".system"),
    ("t.real", ".real"),
    ("(1).__class__", ".__class__"),
    ("(lambda x: x)(t)", "lambda"),
    ("lambda: 1", "lambda"),
    ("[x for x in (t,)]", "comprehension"),
    ("sum(x for x in (t, t))", "sum"),
    ("{x: 1 for x in (t,)}", "comprehension"),
    ("open('f')", "open"),
    ("eval('1')", "eval"),
    ("x + 1", "x"),
    ("e", "e"),
    ("t % 2", "%"),
    ("t // 2", "//"),
    ("t < 1", "comparison"),
    ("t if t else 1", "if-else"),
    ("t and 1", "and/or"),
    ("t[0]", "subscript [...]"),
    ("'abc'", "'abc'"),
    ("True", "True"),
    ("sin(x=t)", "x"),
    ("f'{t}'", "f-string"),
]


@pytest.mark.parametrize(("text", "token"), REJECTED)
def test_rejects_with_file_key_and_token(text, token):
    with pytest.raises(ExpressionError) as info:
        parse_expression(text, where=WHERE)
    msg = str(info.value)
    assert msg.startswith(WHERE + ":")
    assert f"token {token!r}" in msg
    assert "\n" not in msg


@pytest.mark.parametrize(
    "text",
    ["", "sin(", "2 +* t", "sin(t, t)", "atan2(t)", "1" + "0" * 400, "1e999", "a\x00", "x" * 600],
)
def test_other_bad_text_is_one_line_expression_error(text):
    with pytest.raises(ExpressionError) as info:
        parse_expression(text, where=WHERE)
    assert str(info.value).startswith(WHERE + ":") and "\n" not in str(info.value)


@pytest.mark.parametrize("value", [True, None, [1, 2], {"a": 1}, math.nan, math.inf, 10**400])
def test_non_text_values_rejected(value):
    with pytest.raises(ExpressionError, match="followers"):
        parse_expression(value, where=WHERE)


def test_never_evaluates_text(tmp_path):
    marker = tmp_path / "pwned"
    with pytest.raises(ExpressionError):
        parse_expression(f"__import__('pathlib').Path('{marker}').touch()", where=WHERE)
    assert not marker.exists()


def test_function_list_is_the_documented_list():
    assert set(FUNCTIONS) == {
        "sin",
        "cos",
        "tan",
        "exp",
        "log",
        "sqrt",
        "abs",
        "tanh",
        "atan2",
        "min",
        "max",
        "step",
        "sat",
        "smoothstep",
        "prefilter",
        "mod",
    }


def test_mod_is_the_c_remainder():
    e = parse_expression("mod(t, 0.75)", where=WHERE)
    for t in (0.0, 0.5, 0.75, 2.0, 7.3):
        assert e.numpy(t) == pytest.approx(math.fmod(t, 0.75), abs=1e-15)
        assert float(e.casadi(t)) == pytest.approx(math.fmod(t, 0.75), abs=1e-15)


def test_literals_are_parameters_and_the_template_is_the_structure():
    a = parse_expression("4*sin(2*t) + 1 - t**2", where=WHERE)
    b = parse_expression("3*sin(5*t) + 0.5 - t**2", where=WHERE)
    assert a.literals() == (4.0, 2.0, 1.0)  # the exponent stays structure
    assert a.template() == b.template()
    assert a.template() != parse_expression("4*sin(2*t) + 1 - t**3", where=WHERE).template()
    lits = ca.SX.sym("c", 3)
    t = ca.SX.sym("t")
    f = ca.Function("f", [t, lits], [a.casadi(t, lits)])
    for tt in (0.0, 0.3, 2.5):
        # a's template with b's numbers is b, evaluated independently with numpy
        assert float(f(tt, b.literals())) == pytest.approx(float(b.numpy(tt)), rel=1e-15)


def test_a_negative_number_is_a_literal_not_structure():
    # studies draw numbers of either sign: the sign must not change the compiled code
    a = parse_expression("-1.47*step(t - 3) + 2*cos(t)", where=WHERE)
    b = parse_expression("1.47*step(t - 3) + -2*cos(t)", where=WHERE)
    assert a.literals() == (-1.47, 3.0, 2.0) and b.literals() == (1.47, 3.0, -2.0)
    assert a.template() == b.template()
    # a sign in front of anything but a number stays structure
    assert parse_expression("-t", where=WHERE).template() == "(-t)"
    assert parse_expression("t**-2", where=WHERE).literals() == ()
    for tt in (0.0, 2.9, 3.0, 7.5):
        assert float(a.numpy(tt)) == -1.47 * (tt >= 3) + 2 * math.cos(tt)
        assert float(b.casadi(tt)) == 1.47 * (tt >= 3) - 2 * math.cos(tt)
    assert parse_expression("(1.5)**-2", where=WHERE).numpy(0.0) == 1.5**-2


@settings(max_examples=150, deadline=None)
@given(st.text(max_size=60))
def test_fuzz_text_only_toolkit_errors(text):
    try:
        e = parse_expression(text, where=WHERE)
    except ToolkitError:
        return
    e.numpy(np.array([0.0, 1.0]))  # whatever parses also evaluates


@pytest.mark.parametrize("text", [*PAPER, *OTHERS, "mod(t, 1.5) * t**2 - log(t - 3)"])
def test_compiled_numpy_evaluation_is_the_tree_walk_to_the_bit(text):
    # Expr.numpy runs the tree as nested closures; the recursive walk is the reference
    # (same numpy operations in the same order: equal bits, nan where the walk gives nan)
    from core.expressions import _NUMPY, _eval

    e = parse_expression(text, where=WHERE)
    ts = np.linspace(-1.0, 21.0, 1001)
    with np.errstate(all="ignore"):
        walk = np.broadcast_to(_eval(e.node, ts, _NUMPY), ts.shape)
    np.testing.assert_array_equal(np.broadcast_to(e.numpy(ts), ts.shape), walk)
    for t in TIMES:
        with np.errstate(all="ignore"):
            np.testing.assert_array_equal(e.numpy(t), _eval(e.node, np.asarray(t), _NUMPY))


def test_remembered_literals_keep_the_sign_of_zero():
    # the literal, template and breakpoint memories are keyed by the whole expression:
    # trees equal under Python's 0.0 == -0.0 but written differently stay apart
    from core.expressions import Expr

    pos = Expr("0.0 + t", BinOp("+", Num(0.0), Time()))
    neg = Expr("-0.0 + t", BinOp("+", Num(-0.0), Time()))
    assert pos.node == neg.node and hash(pos.node) == hash(neg.node)  # why the text is keyed
    assert math.copysign(1.0, pos.literals()[0]) == 1.0
    assert math.copysign(1.0, neg.literals()[0]) == -1.0
    assert math.copysign(1.0, pos.literals()[0]) == 1.0  # asked again, after neg
    e = parse_expression("3*step(t - 2) + 0.5", where=WHERE)
    assert e.literals() == (3.0, 2.0, 0.5) and e.template() == "((#*step((t-#)))+#)"
    assert e.breakpoints() == (2.0,)


def test_an_expression_is_a_key_by_value_and_travels_without_its_hash():
    # workers get pickled expressions; their string hashes are salted differently
    a = parse_expression("2*cos(t) + step(t - 1)", where=WHERE)
    b = parse_expression("2*cos(t) + step(t - 1)", where=WHERE)
    assert a == b and a is not b and hash(a) == hash(b) == hash((a.text, a.node))
    back = pickle.loads(pickle.dumps(a))
    assert "_hash" not in vars(back) and back == a and hash(back) == hash(a)
    assert back.node == a.node and isinstance(back.node, BinOp)


# --------------------------------------------------------------------------- the tree
def test_every_node_class_has_its_visitor_method():
    assert set(typing.get_args(Node)) == set(METHODS) == {Num, Time, Neg, BinOp, Call}
    assert Visitor.__abstractmethods__ == set(METHODS.values())
    # the walks of the packages implement every method (an abstract one cannot exist)
    import core.faults  # noqa: F401
    import core.shaping  # noqa: F401
    import verify.reference  # noqa: F401

    def subclasses(cls):
        return [d for c in cls.__subclasses__() for d in (c, *subclasses(c))]

    walks = [c for c in subclasses(Visitor) if c.__module__.split(".")[0] in PACKAGES]
    assert {"_Template", "_Eval", "_Closure", "_Text", "_Shape", "_Dual", "_Breaks"} <= {
        c.__qualname__ for c in walks
    }
    assert [c for c in walks if inspect.isabstract(c)] == []


def test_a_visitor_missing_a_method_fails_loudly():
    class NoCall(Visitor[int]):
        def num(self, node: Num) -> int:
            return 0

        def time(self, node: Time) -> int:
            return 0

        def neg(self, node: Neg) -> int:
            return 0

        def binop(self, node: BinOp) -> int:
            return 0

    with pytest.raises(TypeError, match="call"):
        NoCall()
    with pytest.raises(TypeError, match="not an expression node"):
        visit(("num", 1.0), _Parts())  # a tree of tuples is no tree


class _Parts(Visitor[str]):
    """The template and the literals, rebuilt here from the documented rules."""

    def __init__(self) -> None:
        self.literals: list[float] = []

    def num(self, node: Num) -> str:
        self.literals.append(node.value)
        return "#"

    def time(self, node: Time) -> str:
        return "t"

    def neg(self, node: Neg) -> str:
        return "(-" + visit(node.arg, self) + ")"

    def binop(self, node: BinOp) -> str:
        left = visit(node.left, self)
        if node.op == "**" and isinstance(node.right, Num):  # a literal exponent is structure
            return f"({left}**{node.right.value!r})"
        return f"({left}{node.op}{visit(node.right, self)})"

    def call(self, node: Call) -> str:
        return node.name + "(" + ",".join(visit(a, self) for a in node.args) + ")"


@pytest.mark.parametrize(
    "text",
    [*PAPER, *OTHERS, "-1.47*step(t - 3) + 2*cos(t)", "t**-2 - (1.5)**t", "-(t + pi)"],
)
def test_a_visit_reproduces_template_and_literals(text):
    e = parse_expression(text, where=WHERE)
    parts = _Parts()
    assert visit(e.node, parts) == e.template()
    assert tuple(parts.literals) == e.literals()


#: dispatch on a tree of tuples: indexing a node, comparing its kind, a kind-tagged tuple
TUPLE_DISPATCH = re.compile(
    r"\bnode\w*\[\d+\]"
    r"|\bkind\s*(?:==|in)\s*\(?\s*\"(?:num|t|neg|bin|call)\""
    r"|(?<![\w)\]])\(\s*\"(?:num|neg|bin|call)\"\s*,"
    r"|\(\s*\"t\"\s*,\s*\)"
)


def test_no_module_dispatches_on_a_tuple_tree():
    found = []
    for pkg in (*PACKAGES, "search"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if TUPLE_DISPATCH.search(line):
                    found.append(f"{path.relative_to(ROOT).as_posix()}:{k}: {line.strip()}")
    assert found == [], "tuple-tree dispatch (use core.expression_tree.Visitor):\n" + "\n".join(
        found
    )


@pytest.mark.parametrize(
    ("line", "bad"),
    [
        ("    kind = node[0]", True),
        ('    if kind == "bin":', True),
        ('    if kind in ("num", "t"):', True),
        ('    return ("call", name, tuple(args))', True),
        ('    x = ("bin", "-", ("t",), ("num", t0))', True),
        ('    return ("t",)', True),
        ('    for need in ("t", "eta0_1", "p1_1"):', False),
        ('    lo = -expression_sup("neg", (expr,), ts)', False),
        ('    return {"abs": np.abs, "neg": np.negative}[kind](v)', False),
        ('    a = float(self.take(kind="num"))', False),
        ('    return Call("step", (BinOp("-", Time(), Num(t0)),))', False),
    ],
)
def test_the_tuple_dispatch_grep_can_fail(line, bad):
    assert bool(TUPLE_DISPATCH.search(line)) is bad


def test_walker_search_and_transformer_defaults():
    from core.expression_tree import Search, Transformer, Walker

    e = parse_expression("-(2*t) + max(3, sin(t)**2)")

    class Numbers(Walker):
        def __init__(self):
            self.seen = []

        def num(self, node):
            self.seen.append(node.value)

    w = Numbers()
    visit(e.node, w)
    assert w.seen == [2.0, 3.0, 2.0]  # every child, left to right
    assert visit(e.node, Transformer()) == e.node  # the identity rebuild

    class CallsSin(Search):
        def call(self, node):
            return node.name == "sin" or super().call(node)

    assert visit(e.node, CallsSin()) and not visit(e.node, Search())
    assert not visit(parse_expression("max(3, cos(t))").node, CallsSin())

    class Double(Transformer):
        def num(self, node):
            return Num(2 * node.value)

    doubled = visit(e.node, Double())
    assert doubled != e.node
    assert [n.value for n in _nums(doubled)] == [4.0, 6.0, 4.0]


def _nums(node):
    if isinstance(node, Num):
        return [node]
    if isinstance(node, Neg):
        return _nums(node.arg)
    if isinstance(node, BinOp):
        return _nums(node.left) + _nums(node.right)
    if isinstance(node, Call):
        return [n for a in node.args for n in _nums(a)]
    return []
