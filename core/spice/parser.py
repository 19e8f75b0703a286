"""A SPICE netlist subset, parsed by estim itself (no well-kept Python parser of SPICE
netlists covers ``.subckt``, ``.param`` expressions and error positions; PySpice drives
ngspice rather than reading netlists, and the format is small).

Accepted (case-insensitive; the first line is the title; ``*`` starts a comment line, ``;``
or ``$`` a comment to the end of the line; a line starting with ``+`` continues the one
before):

* ``R``, ``C``, ``L`` ``name n1 n2 value``;
* ``V``, ``I`` ``name n+ n- [DC] value | SIN(vo va f [td [theta [phase]]]) |
  PULSE(v1 v2 [td tr tf pw per]) | PWL(t1 v1 t2 v2 ...)``;
* ``E``, ``G`` ``name n+ n- nc+ nc- value`` (voltage-controlled voltage and current
  sources); ``F``, ``H`` ``name n+ n- vsource value`` (current-controlled current and
  voltage sources, by the current of a voltage source: docs/deviations.md D76);
* ``B name n+ n- I={expression}`` (a current of node voltages ``v(a)``, ``v(a,b)``:
  :mod:`estim.spice.behavioural`);
* ``D name anode cathode model``, ``Q name c b e model``, ``M name d g s b model``;
* ``X name nodes... subckt`` with ``.subckt name pins... [params: k=v ...]`` / ``.ends``,
  one level deep;
* ``.param name=expr ...`` (``+ - * / ** ^``, parentheses, ``exp log sqrt abs min max``,
  earlier params; braces ``{expr}`` around an expression where a value stands);
* ``.model name type(k=v ...)``, ``.ic v(node)=value ...``, ``.end``; ``.include`` and
  ``.lib`` are refused (a model they would bring in would be missing); other dot lines
  (``.tran``, ``.options``, ...) are read over.

Values take SI suffixes ``f p n u m k meg g t`` (and ``mil``); letters after a number or
suffix are units and are ignored (``10uF``, ``4.7kOhm``). Every error is a
:class:`NetlistError`: one line naming the file, the line number and what is wrong.
"""

from __future__ import annotations

import ast
import collections
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from estim.errors import EstimError
from estim.spice import behavioural

SUFFIXES = {"f": 1e-15, "p": 1e-12, "n": 1e-9, "u": 1e-6, "m": 1e-3, "k": 1e3,
            "meg": 1e6, "g": 1e9, "t": 1e12, "mil": 25.4e-6}
_NUMBER = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?)(meg|mil|[fpnumkgt])?([a-z]*)$")
_FUNCTIONS = {"exp": math.exp, "log": math.log, "ln": math.log, "sqrt": math.sqrt,
              "abs": abs, "min": min, "max": max, "pow": pow}
_ARITY = {"r": 2, "c": 2, "l": 2, "v": 2, "i": 2, "e": 4, "g": 4, "f": 2, "h": 2, "d": 2,
          "q": 3, "m": 4, "b": 2}
MAX_LINES = 100_000
"""A netlist longer than this is refused (a generated netlist of that size is a mistake)."""


class NetlistError(EstimError, ValueError):
    """A netlist that cannot be read: ``file:line: message``."""

    def __init__(self, source: str, line: int, message: str) -> None:
        self.source, self.line, self.message = source, line, message
        where = f"{source}:{line}: " if line else f"{source}: "
        super().__init__(where + message)


@dataclass(frozen=True)
class Element:
    """One circuit element: its kind (first letter), name, nodes, value or waveform, the
    model or source it names, and where it was written."""

    kind: str
    name: str
    nodes: tuple[str, ...]
    value: float | None = None
    waveform: tuple | None = None
    ref: str | None = None
    line: int = 0
    size: tuple = ()
    """An M line's ``W`` and ``L`` as ``(("w", value), ("l", value))``, those it gives."""


@dataclass(frozen=True)
class DeviceModel:
    name: str
    type: str
    params: dict
    line: int = 0


@dataclass
class Netlist:
    """Elements with subcircuits expanded, models, initial conditions, parameters."""

    title: str
    source: str
    elements: list = field(default_factory=list)
    models: dict = field(default_factory=dict)
    ic: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)

    def element(self, name: str) -> Element | None:
        return next((e for e in self.elements if e.name == name.lower()), None)


def _scaled(number: str, suffix: str | None) -> float:
    """``number`` times its SI ``suffix``, rounded once: ``10u`` is read as ``10e-6`` (the
    double nearest 1e-5), not as ``10 * 1e-6`` (one unit in the last place below it)."""
    if suffix and suffix != "mil" and "e" not in number:
        return float(f"{number}e{round(math.log10(SUFFIXES[suffix]))}")
    return float(number) * SUFFIXES.get(suffix or "", 1.0)


def with_numbers(text: str) -> str:
    """``text`` with each number that carries an SI suffix written out (``1m`` -> ``0.001``)."""
    return re.sub(r"(?<![\w.])((?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?)(meg|mil|[fpnumkgt])(?![\w(])",
                  lambda mm: repr(_scaled(mm.group(1), mm.group(2))), text)


def evaluate(text: str, params: dict, where: tuple[str, int]) -> float:
    """A number with an SI suffix, or an expression of numbers, ``params`` and the
    functions of :data:`_FUNCTIONS`."""
    text = text.strip().lower()
    if text.startswith("{") and text.endswith("}"):
        text = text[1:-1]
    m = _NUMBER.match(text)
    if m and m.group(3).startswith("e") and "e" not in m.group(1):
        raise NetlistError(*where, f"{text!r}: an exponent 'e' with no digits")
    if m and m.group(2) and "e" in m.group(1):
        raise NetlistError(*where, f"{text!r}: both an exponent and a scale suffix; write "
                           "one of them")
    if m:
        value = _scaled(m.group(1), m.group(2))
        if not math.isfinite(value) or (value == 0 and any(c in "123456789" for c in
                                                            m.group(1).partition("e")[0])):
            raise NetlistError(*where, f"{text!r} is beyond the range of a double")
        return value
    if text in params:
        return params[text]
    expr = with_numbers(text).replace("^", "**")
    if len(expr) > 1000:            # before parsing: a deep expression exhausts the parser
        raise NetlistError(*where, "expression longer than 1000 characters")
    literal = re.search(r"(?<![\w.])(0[xob]\w*|\d[\d.]*_\w*)", expr)
    if literal:
        raise NetlistError(*where, f"{literal.group(1)!r} in {text!r} is not a SPICE number "
                           "(no hexadecimal, octal, binary or digit separators)")
    try:
        tree = ast.parse(expr, mode="eval")
    except (SyntaxError, MemoryError, RecursionError):
        raise NetlistError(*where, f"{text!r} is not a number or an expression") from None

    def walk(node):
        if isinstance(node, ast.Expression):
            return walk(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.Name):
            if node.id in params:
                return params[node.id]
            raise NetlistError(*where, f"unknown parameter {node.id!r} in {text!r}")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            v = walk(node.operand)
            return v if isinstance(node.op, ast.UAdd) else -v
        if isinstance(node, ast.BinOp):
            a, b = walk(node.left), walk(node.right)
            ops = {ast.Add: lambda: a + b, ast.Sub: lambda: a - b, ast.Mult: lambda: a * b,
                   ast.Div: lambda: a / b, ast.Pow: lambda: a ** b}
            op = ops.get(type(node.op))
            if op is None:
                raise NetlistError(*where, f"operator not allowed in {text!r}")
            if isinstance(node.op, ast.Pow) and abs(b) > 1e3:
                raise NetlistError(*where, f"exponent too large in {text!r}")
            return op()
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in _FUNCTIONS and not node.keywords:
            return float(_FUNCTIONS[node.func.id](*[walk(a) for a in node.args]))
        raise NetlistError(*where, f"{text!r} is not a number or an expression")

    try:
        value = walk(tree)
    except (ZeroDivisionError, OverflowError, ValueError, TypeError) as exc:
        if isinstance(exc, NetlistError):
            raise
        raise NetlistError(*where, f"{text!r} cannot be evaluated ({exc})") from None
    if not math.isfinite(value):
        raise NetlistError(*where, f"{text!r} is not finite")
    return value


def _logical_lines(text: str, source: str) -> list[tuple[int, str]]:
    """(line number, text) with comments removed and continuations joined; the title line
    is line 1 and is returned as is."""
    raw = text.splitlines()
    if len(raw) > MAX_LINES:
        raise NetlistError(source, 0, f"more than {MAX_LINES} lines")
    out: list[tuple[int, list[str]]] = []       # each line's parts, joined once at the end
    for number, line in enumerate(raw, start=1):
        if number == 1:
            out.append((1, [line.strip()]))
            continue
        line = re.split(r"[;$]", line, maxsplit=1)[0].rstrip()
        stripped = line.strip()
        if not stripped or stripped.startswith("*"):
            continue
        if stripped.startswith("+"):
            if len(out) < 2:
                raise NetlistError(source, number, "a continuation line ('+') with no line "
                                   "before it")
            out[-1][1].append(stripped[1:])
            continue
        out.append((number, [stripped]))
    return [(number, " ".join(parts)) for number, parts in out]


def _tokens(line: str) -> list[str]:
    """Split on blanks, keeping ``name(...)`` and ``{...}`` together, ``=`` as a token."""
    line = re.sub(r"\s*=\s*", "=", line)
    line = re.sub(r"\s*\(\s*", "(", line)
    tokens, depth, current = [], 0, ""
    for ch in line:
        if ch in "({":
            depth += 1
        elif ch in ")}":
            depth -= 1
        if ch.isspace() and depth == 0:
            if current:
                tokens.append(current)
            current = ""
        else:
            current += ch
    if depth:
        raise ValueError("unbalanced parentheses or braces")
    if current:
        tokens.append(current)
    return tokens


def _assignments(tokens: list[str], params: dict, where) -> dict:
    out = {}
    for tok in tokens:
        if "=" not in tok:
            raise NetlistError(*where, f"expected name=value, got {tok!r}")
        name, _, value = tok.partition("=")
        if not re.fullmatch(r"[a-z_][a-z0-9_]*", name):
            raise NetlistError(*where, f"{name!r} is not a parameter name")
        out[name] = evaluate(value, {**params, **out}, where)
    return out


def _waveform(tokens: list[str], params: dict, where) -> tuple:
    """A source's value: ``("dc", v)``, ``("sin", ...)``, ``("pulse", ...)``, ``("pwl", ...)``."""
    if not tokens:
        raise NetlistError(*where, "a source needs a value")
    toks = tokens[1:] if tokens[0] == "dc" else tokens
    if not toks:
        raise NetlistError(*where, "a source needs a value after DC")
    head = toks[0]
    m = re.fullmatch(r"(sin|pulse|pwl)\((.*)\)", head)
    if m:
        kind = m.group(1)
        args = [evaluate(a, params, where) for a in m.group(2).replace(",", " ").split()]
        need = {"sin": (3, 6), "pulse": (2, 7), "pwl": (2, 10**6)}[kind]
        if not need[0] <= len(args) <= need[1]:
            raise NetlistError(*where, f"{kind.upper()} takes {need[0]} to {need[1]} values, "
                               f"got {len(args)}")
        if kind == "pwl":
            if len(args) % 2:
                raise NetlistError(*where, "PWL takes pairs of time and value")
            times = args[0::2]
            if any(b < a for a, b in zip(times, times[1:], strict=False)):
                raise NetlistError(*where, "PWL times must not decrease")
        return (kind, *args)
    if len(toks) != 1:
        raise NetlistError(*where, f"unexpected {' '.join(toks[1:])!r} after the value")
    return ("dc", evaluate(head, params, where))


def parse(text: str, source: str = "<netlist>") -> Netlist:
    """The netlist in ``text`` (named ``source`` in messages), subcircuits expanded."""
    lines = _logical_lines(text, source)
    if not lines:
        raise NetlistError(source, 0, "empty netlist")
    net = Netlist(title=lines[0][1], source=source)
    subckts: dict[str, tuple] = {}
    body: list[tuple[int, list[str]]] = []
    open_sub: tuple | None = None
    ended = False
    for number, line in lines[1:]:
        where = (source, number)
        if ended:
            break
        try:
            tokens = _tokens(line.lower())
        except ValueError as exc:
            raise NetlistError(*where, str(exc)) from None
        head = tokens[0]
        if head in (".include", ".inc", ".lib"):       # read over, a model it holds was lost
            raise NetlistError(*where, f"{head} is not supported: put the lines it would bring "
                               "into this file")
        if head == ".end":
            ended = True
            continue
        if head == ".subckt":
            if open_sub is not None:
                raise NetlistError(*where, "a .subckt inside another (one level only)")
            if len(tokens) < 3:
                raise NetlistError(*where, ".subckt needs a name and its pins")
            pins = [t for t in tokens[2:] if "=" not in t and t != "params:"]
            defaults = [t for t in tokens[2:] if "=" in t]
            open_sub = (tokens[1], pins, _assignments(defaults, net.params, where), [],
                        number)
            continue
        if head == ".ends":
            if open_sub is None:
                raise NetlistError(*where, ".ends with no .subckt")
            subckts[open_sub[0]] = open_sub
            open_sub = None
            continue
        if open_sub is not None:
            if head == ".param":
                raise NetlistError(*where, ".param inside a .subckt: use its params: line")
            open_sub[3].append((number, tokens))
            continue
        if head == ".param":
            net.params.update(_assignments(tokens[1:], net.params, where))
            continue
        body.append((number, tokens))
    if open_sub is not None:
        raise NetlistError(source, open_sub[4], f".subckt {open_sub[0]} has no .ends")
    for number, tokens in body:
        where = (source, number)
        head = tokens[0]
        if head == ".model":
            _model(net, tokens, where)
        elif head == ".ic":
            for tok in tokens[1:]:
                m = re.fullmatch(r"v\(([^()]+)\)=(.+)", tok)
                if not m:
                    raise NetlistError(*where, f"expected v(node)=value in .ic, got {tok!r}")
                net.ic[m.group(1)] = evaluate(m.group(2), net.params, where)
        elif head.startswith("."):
            continue
        elif head[0] == "x":
            _instance(net, tokens, subckts, where)
        else:
            net.elements.append(_element(tokens, net.params, where))
    for number, tokens in (b for s in subckts.values() for b in s[3]):
        if tokens[0] == ".model":
            _model(net, tokens, (source, number))
    names = collections.Counter(e.name for e in net.elements)
    for e in net.elements:
        if names[e.name] > 1:
            raise NetlistError(source, e.line, f"element {e.name} is defined twice")
    return net


def _model(net: Netlist, tokens: list[str], where) -> None:
    if len(tokens) < 3:
        raise NetlistError(*where, ".model needs a name and a type")
    rest = " ".join(tokens[2:])
    m = re.fullmatch(r"([a-z]+)(?:\((.*)\))?(.*)", rest)
    if not m:
        raise NetlistError(*where, f"cannot read the model type in {rest!r}")
    kind = m.group(1)
    args = (m.group(2) or "").replace(",", " ").split() + m.group(3).split()
    net.models[tokens[1]] = DeviceModel(tokens[1], kind, _assignments(args, net.params, where),
                                        where[1])


def _element(tokens: list[str], params: dict, where, prefix: str = "",
             rename=lambda n: n) -> Element:
    name = tokens[0]
    kind = name[0]
    if kind not in _ARITY:
        raise NetlistError(*where, f"unknown element {name!r} (R C L V I E G F H B D Q M X "
                           "are read)")
    arity = _ARITY[kind]
    if len(tokens) < arity + 2:
        raise NetlistError(*where, f"{name} needs {arity} nodes and a "
                           f"{'model' if kind in 'dqm' else 'value'}")
    nodes = tuple(rename(n) for n in tokens[1:1 + arity])
    rest = tokens[1 + arity:]
    full = prefix + name
    if kind == "b":
        law = " ".join(rest)
        if law[:2] == "v=":
            raise NetlistError(*where, f"{name}: a behavioural voltage source (V=) fixes a node "
                               "by a nonlinear law, which estim's explicit model does not "
                               "solve (D71); write it as a current (I=) into a node with a "
                               "capacitor")
        if law[:2] != "i=":
            raise NetlistError(*where, f"{name}: expected I={{expression}} after the nodes")
        try:
            expr, controls = behavioural.read(with_numbers(law[2:]), params, rename)
        except ValueError as err:
            raise NetlistError(*where, str(err)) from None
        return Element(kind, full, nodes + controls, ref=expr, line=where[1])
    if kind == "m" and len(rest) > 1:
        size = []
        for token in rest[1:]:
            key, _, text = token.partition("=")
            if key not in ("w", "l") or not text or key in dict(size):
                raise NetlistError(*where, f"{name}: expected w=VALUE and l=VALUE after the "
                                   f"model name, got {token!r}")
            value = evaluate(text, params, where)
            if not value > 0:
                raise NetlistError(*where, f"{name}: {key} must be positive, got {value:g}")
            size.append((key, value))
        return Element(kind, full, nodes, ref=rest[0], line=where[1], size=tuple(size))
    if kind in "dqm":
        if len(rest) != 1:
            raise NetlistError(*where, f"{name}: expected one model name after the nodes")
        return Element(kind, full, nodes, ref=rest[0], line=where[1])
    if kind in "fh":
        if len(rest) != 2:
            raise NetlistError(*where, f"{name}: expected a controlling source and a value")
        return Element(kind, full, nodes, value=evaluate(rest[1], params, where),
                       ref=prefix + rest[0], line=where[1])
    if kind in "vi":
        return Element(kind, full, nodes, waveform=_waveform(rest, params, where),
                       line=where[1])
    if len(rest) != 1:
        raise NetlistError(*where, f"{name}: expected one value after the nodes, got "
                           f"{' '.join(rest)!r}")
    value = evaluate(rest[0], params, where)
    if kind in "rcl" and not value > 0:
        raise NetlistError(*where, f"{name}: the value must be positive, got {value:g}")
    return Element(kind, full, nodes, value=value, line=where[1])


def _instance(net: Netlist, tokens: list[str], subckts: dict, where) -> None:
    name = tokens[0]
    args = [t for t in tokens[1:] if "=" not in t and t != "params:"]
    overrides = [t for t in tokens[1:] if "=" in t]
    if not args:
        raise NetlistError(*where, f"{name}: expected nodes and a subcircuit name")
    sub = subckts.get(args[-1])
    if sub is None:
        raise NetlistError(*where, f"{name}: unknown subcircuit {args[-1]!r}")
    _, pins, defaults, body, _ = sub
    nodes = args[:-1]
    if len(nodes) != len(pins):
        raise NetlistError(*where, f"{name}: subcircuit {args[-1]} has {len(pins)} pins, "
                           f"called with {len(nodes)}")
    local = {**net.params, **defaults, **_assignments(overrides, net.params, where)}
    mapping = dict(zip(pins, nodes, strict=True))

    def rename(node: str) -> str:
        if node in mapping:
            return mapping[node]
        return node if node in ("0", "gnd") else f"{name}.{node}"

    for number, toks in body:
        if toks[0].startswith("x"):
            raise NetlistError(net.source, number, "a subcircuit inside a subcircuit "
                               "(one level only)")
        if toks[0].startswith("."):
            continue
        net.elements.append(_element(toks, local, (net.source, number), f"{name}.", rename))


def read(path: str | Path) -> Netlist:
    """Parse the netlist file at ``path``."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise NetlistError(str(p), 0, f"cannot read it ({exc.__class__.__name__})") from None
    return parse(text, str(p))


def with_params(text: str, lines: list[str]) -> str:
    """The netlist ``text`` with its ``.param`` values replaced by those of ``lines``: all of
    them on one line where the first ``.param`` was (after the title if there was none), the
    other ``.param`` lines and their continuations blanked, so that every element keeps its
    line number for the messages."""
    rows = text.splitlines()
    merged = ".param " + " ".join(line.split(None, 1)[1] for line in lines)
    out, in_param, placed = [rows[0]], False, False
    for r in rows[1:]:
        s = r.strip().lower()
        if s.startswith(".param") or (in_param and s.startswith("+")):
            in_param = True
            out.append("*" if placed else merged)
            placed = True
            continue
        in_param = False
        out.append(r)
    if not placed:
        out.insert(1, merged)
    return "\n".join(out)
