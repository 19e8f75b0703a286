"""Behavioural current sources (SPICE's ``B`` element with ``I=``): ``Bname n+ n-
I={expression}``, the current from ``n+`` through the source to ``n-`` a function of node
voltages ``v(node)`` and ``v(node,node)``, numbers, ``.param`` values and the functions of
:data:`FUNCTIONS`. The expression is read once into a Python expression of ``_v``, the
voltages of its control nodes (stored as the element's ``ref``, the control nodes after its
two terminals); its slopes are exact by the complex step (``Im f(v + i h e_j) / h``), its
second slopes central differences of them. A ``V=`` source would fix a node by a nonlinear
law, which estim's explicit model does not solve (D71): refused by name.
"""

from __future__ import annotations

import ast
import re

import numpy as np

STEP = 1e-20
"""The complex step: no subtraction, so any step below the voltages' rounding is exact."""


def _abs(x):
    return x * np.sign(np.real(x))


def _min(a, b):
    return np.where(np.real(a) <= np.real(b), a, b)


def _max(a, b):
    return np.where(np.real(a) >= np.real(b), a, b)


FUNCTIONS = {"exp": np.exp, "ln": np.log, "log": np.log, "sqrt": np.sqrt, "abs": _abs,
             "min": _min, "max": _max, "pow": np.power, "tanh": np.tanh, "sin": np.sin,
             "cos": np.cos, "atan": np.arctan, "sinh": np.sinh, "cosh": np.cosh}
"""The functions an expression may call (``log`` is the natural logarithm, as ``ln``);
each takes a complex argument, so the complex step differentiates through it (``abs``,
``min`` and ``max`` by the sign of the real part)."""

NGSPICE_NAMES = {"log": "ln"}

_VOLTAGE = re.compile(r"\bv\(\s*([^,()\s]+)\s*(?:,\s*([^,()\s]+)\s*)?\)")


def read(text: str, params: dict, rename) -> tuple[str, tuple[str, ...]]:
    """``(expression of _v, control nodes)`` of a B element's ``I=`` text: each ``v(a)`` or
    ``v(a,b)`` becomes ``_v[i]`` or ``(_v[i] - _v[j])`` over the control nodes (renamed by
    ``rename``, as a subcircuit's are), each ``.param`` its value; a ``ValueError`` naming
    what is not allowed (the parser's ``NetlistError`` says where)."""
    text = text.strip()
    if text.startswith("{") and text.endswith("}"):
        text = text[1:-1]
    nodes: list[str] = []

    def index(name: str) -> str:
        name = rename(name)
        if name in ("0", "gnd"):
            return "0.0"
        if name not in nodes:
            nodes.append(name)
        return f"_v[{nodes.index(name)}]"

    def voltage(m: re.Match) -> str:
        a = index(m.group(1))
        return a if m.group(2) is None else f"({a} - {index(m.group(2))})"

    expr = _VOLTAGE.sub(voltage, text.lower()).replace("^", "**")
    if len(expr) > 2000:
        raise ValueError("B expression longer than 2000 characters")
    try:
        tree = ast.parse(expr, mode="eval")
    except (SyntaxError, RecursionError):
        raise ValueError(f"{text!r} is not an expression of v(node), numbers, "
                           "parameters and functions") from None

    class Fold(ast.NodeTransformer):
        def visit_Name(self, node):
            if node.id == "_v":
                return node
            if node.id in params:
                return ast.Constant(float(params[node.id]))
            raise ValueError(f"unknown name {node.id!r} in {text!r}: a .param, or "
                               "v(node)")

        def visit_Call(self, node):
            if not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS
                    and not node.keywords):
                name = getattr(node.func, "id", "?")
                raise ValueError(f"function {name!r} in {text!r}; expected one of "
                                   f"{', '.join(sorted(FUNCTIONS))}")
            node.args = [self.visit(a) for a in node.args]
            return node

        def visit_Subscript(self, node):
            return node                            # _v[i], made above

        def visit_Constant(self, node):
            if not isinstance(node.value, (int, float)) or isinstance(node.value, bool):
                raise ValueError(f"{node.value!r} in {text!r} is not a number")
            return ast.Constant(float(node.value))

        def generic_visit(self, node):
            allowed = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Subscript, ast.Load,
                       ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.UAdd, ast.USub)
            if not isinstance(node, allowed):
                raise ValueError(f"{type(node).__name__.lower()} not allowed in "
                                   f"{text!r}")
            return super().generic_visit(node)

    tree = ast.fix_missing_locations(Fold().visit(tree))
    return ast.unparse(tree), tuple(nodes)


def compiled(expr: str):
    """The expression as a function of ``_v`` (a sequence of arrays)."""
    code = compile(expr, "<B source>", "eval")
    return lambda v: eval(code, {"__builtins__": {}, **FUNCTIONS}, {"_v": v})


def current_and_slopes(fn, V: np.ndarray, idx: list) -> tuple[np.ndarray, np.ndarray]:
    """The current ``(...)`` at node voltages ``V (..., nodes)`` and its slopes w.r.t. the
    control nodes ``idx`` (``(..., len(idx))``), by the complex step."""
    V = np.asarray(V, float)
    base = [V[..., i] for i in idx]
    cur = np.real(fn([b + 0j for b in base])) + np.zeros(V.shape[:-1])
    slopes = []
    for j in range(len(idx)):
        moved = [b + (1j * STEP if k == j else 0j) for k, b in enumerate(base)]
        slopes.append(np.imag(fn(moved)) / STEP + np.zeros(V.shape[:-1]))
    return cur, (np.stack(slopes, axis=-1) if slopes else np.zeros(V.shape[:-1] + (0,)))


def ngspice(expr: str, nodes: tuple[str, ...], flat) -> str:
    """The expression in ngspice's syntax: ``_v[i]`` as ``v(node)``, ``**`` as ``^``."""
    class Write(ast.NodeVisitor):
        def visit(self, node):
            if isinstance(node, ast.Expression):
                return self.visit(node.body)
            if isinstance(node, ast.Constant):
                return repr(float(node.value))
            if isinstance(node, ast.Subscript):
                return f"v({flat(nodes[node.slice.value])})"
            if isinstance(node, ast.UnaryOp):
                sign = "-" if isinstance(node.op, ast.USub) else "+"
                return f"({sign}{self.visit(node.operand)})"
            if isinstance(node, ast.BinOp):
                op = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/",
                      ast.Pow: "^"}[type(node.op)]
                return f"({self.visit(node.left)} {op} {self.visit(node.right)})"
            name = NGSPICE_NAMES.get(node.func.id, node.func.id)
            return f"{name}({', '.join(self.visit(a) for a in node.args)})"

    return Write().visit(ast.parse(expr, mode="eval"))
