"""A small, explicit grammar for the function expressions of Adams datasets — parsed, never
`eval`-ed.

spec: stiffness §4.1 (the GFORCE of `model_exemple11`: ``1000*sin(pi*(time+0.15))``).

Grammar (case-insensitive; whitespace and line breaks are ignored)::

    expression := term (("+" | "-") term)*
    term       := unary (("*" | "/") unary)*
    unary      := ("+" | "-") unary | atom
    atom       := number ["D"] | "PI" | "TIME" | function "(" expression ("," expression)* ")"
                | "(" expression ")"
    function   := "SIN" | "COS" | "STEP" | "DM"

- a number may carry Adams's degree suffix ``D`` (``30D`` = π/6);
- ``STEP(x, x0, h0, x1, h1)`` is Adams's cubic step: h0 for x ≤ x0, h1 for x ≥ x1, and
  h0 + (h1 − h0)·Δ²·(3 − 2Δ) with Δ = (x − x0)/(x1 − x0) in between;
- ``DM(i, j)`` (distance between markers i and j) is recognised so that a GCON of the form
  ``DM(i, j) - L`` can be read as a distance constraint; it has no numeric value here.

Anything else (``**``, other functions, other names, USER subroutines) is an `ExpressionError`
with the offending position, so the caller can report the statement and skip it.
"""

import math
import re
from dataclasses import dataclass

MAX_DEPTH = 64
"""Deepest nesting of parentheses and unary signs accepted (deeper is an `ExpressionError`)."""

MAX_TOKENS = 600
"""Longest expression accepted, in tokens (longer is an `ExpressionError`; it also bounds the
depth of the tree, so evaluating it never exhausts Python's stack)."""

FUNCTIONS = {"SIN": 1, "COS": 1, "STEP": 5, "DM": 2}
"""Functions of the grammar and their number of arguments."""

_SPACE = re.compile(r"\s*")
_TOKEN = re.compile(
    r"(?:"
    r"(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)(?P<deg>[dD](?![A-Za-z0-9_]))?"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
    r"|(?P<op>[-+*/(),])"
    r")"
)


class ExpressionError(ValueError):
    """An expression outside the grammar; `position` is the character offset in the text."""

    def __init__(self, message: str, position: int):
        self.position = position
        super().__init__(message)


@dataclass(frozen=True)
class Node:
    """Expression tree node: `kind` is 'number', 'name', 'negate', 'binary' or 'call'."""

    kind: str
    value: float | str | None = None
    children: tuple["Node", ...] = ()


def _tokens(text: str):
    pos, n = 0, len(text)
    out = []
    while True:
        pos = _SPACE.match(text, pos).end()
        if pos >= n:
            break
        m = _TOKEN.match(text, pos)
        if m is None:
            raise ExpressionError(f"unexpected character {text[pos]!r}", pos)
        start = pos
        if m.group("number") is not None:
            value = float(m.group("number"))
            if not math.isfinite(value):
                raise ExpressionError(f"number {m.group('number')} is not finite", start)
            if m.group("deg"):
                value = math.radians(value)
            out.append(("number", value, start))
        elif m.group("name") is not None:
            out.append(("name", m.group("name").upper(), start))
        else:
            out.append(("op", m.group("op"), start))
        pos = m.end()
        if len(out) > MAX_TOKENS:
            raise ExpressionError(f"expression longer than {MAX_TOKENS} tokens", start)
    out.append(("end", None, len(text)))
    return out


class _Parser:
    def __init__(self, text: str):
        self.tokens = _tokens(text)
        self.i = 0
        self.depth = 0

    def peek(self):
        return self.tokens[self.i]

    def take(self):
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def expect(self, op):
        tok = self.take()
        if tok[0] != "op" or tok[1] != op:
            raise ExpressionError(f"expected {op!r}", tok[2])

    def enter(self, pos):
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExpressionError(f"expression nested deeper than {MAX_DEPTH} levels", pos)

    def binary(self, ops: str, operand) -> Node:
        """Left-associative `operand (op operand)*` with `op` one of `ops`."""
        node = operand()
        while self.peek()[0] == "op" and self.peek()[1] in ops:
            op = self.take()[1]
            node = Node("binary", op, (node, operand()))
        return node

    def expression(self) -> Node:
        return self.binary("+-", self.term)

    def term(self) -> Node:
        return self.binary("*/", self.unary)

    def unary(self) -> Node:
        tok = self.peek()
        if tok[0] == "op" and tok[1] in "+-":
            self.take()
            self.enter(tok[2])
            inner = self.unary()
            self.depth -= 1
            return Node("negate", None, (inner,)) if tok[1] == "-" else inner
        return self.atom()

    def atom(self) -> Node:
        kind, value, pos = self.take()
        if kind == "number":
            return Node("number", value)
        if kind == "op" and value == "(":
            self.enter(pos)
            node = self.expression()
            self.expect(")")
            self.depth -= 1
            return node
        if kind == "name":
            if value in ("PI", "TIME"):
                return Node("name", value)
            if value in FUNCTIONS:
                self.expect("(")
                self.enter(pos)
                args = [self.expression()]
                while self.peek()[0] == "op" and self.peek()[1] == ",":
                    self.take()
                    args.append(self.expression())
                self.expect(")")
                self.depth -= 1
                if len(args) != FUNCTIONS[value]:
                    raise ExpressionError(
                        f"{value} takes {FUNCTIONS[value]} argument(s), got {len(args)}", pos
                    )
                return Node("call", value, tuple(args))
            raise ExpressionError(
                f"'{value}' is not in the expression grammar (numbers, + - * /, parentheses, "
                f"PI, TIME, {', '.join(FUNCTIONS)})", pos
            )
        if kind == "end":
            raise ExpressionError("expression ends too early", pos)
        raise ExpressionError(f"unexpected {value!r}", pos)


def parse_expression(text: str) -> Node:
    """Parse `text` into an expression tree (raises `ExpressionError`)."""
    parser = _Parser(text)
    node = parser.expression()
    kind, value, pos = parser.peek()
    if kind != "end":
        raise ExpressionError(f"unexpected {value!r} after the expression", pos)
    return node


def _step(x, x0, h0, x1, h1):
    if x1 <= x0:
        raise ExpressionError("STEP needs x1 > x0", 0)
    if x <= x0:
        return h0
    if x >= x1:
        return h1
    d = (x - x0) / (x1 - x0)
    return h0 + (h1 - h0) * d * d * (3.0 - 2.0 * d)


def evaluate(node: Node, time: float = 0.0) -> float:
    """Value of an expression tree at simulation time `time` (s)."""
    if node.kind == "number":
        return float(node.value)
    if node.kind == "name":
        return math.pi if node.value == "PI" else float(time)
    if node.kind == "negate":
        return -evaluate(node.children[0], time)
    if node.kind == "binary":
        a, b = (evaluate(c, time) for c in node.children)
        if node.value == "+":
            out = a + b
        elif node.value == "-":
            out = a - b
        elif node.value == "*":
            out = a * b
        else:
            if b == 0.0:
                raise ExpressionError("division by zero", 0)
            out = a / b
        if not math.isfinite(out):
            raise ExpressionError("the expression overflows", 0)
        return out
    args = [evaluate(c, time) for c in node.children] if node.value != "DM" else []
    if node.value == "SIN":
        return math.sin(args[0])
    if node.value == "COS":
        return math.cos(args[0])
    if node.value == "STEP":
        return _step(*args)
    raise ExpressionError(f"{node.value}(...) has no numeric value in a static model", 0)


def depends_on_time(node: Node) -> bool:
    """Whether the expression uses TIME."""
    if node.kind == "name":
        return node.value == "TIME"
    return any(depends_on_time(c) for c in node.children)


def evaluate_text(text: str, time: float = 0.0) -> float:
    """Parse and evaluate `text` at `time` (raises `ExpressionError`)."""
    return evaluate(parse_expression(text), time)


def distance_constraint(node: Node) -> tuple[int, int, float] | None:
    """If `node` is ``DM(i, j) - L`` (or ``DM(i, j)``, or ``-L + DM(i, j)``) with integer marker
    ids and a constant L, return (i, j, L); otherwise None."""

    def dm(n):
        if n.kind == "call" and n.value == "DM":
            ids = []
            for c in n.children:
                if c.kind != "number" or float(c.value) != int(c.value):
                    return None
                ids.append(int(c.value))
            return ids
        return None

    def constant(n):
        if depends_on_time(n) or _contains_dm(n):
            return None
        try:
            return evaluate(n)
        except ExpressionError:
            return None

    if (ids := dm(node)) is not None:
        return ids[0], ids[1], 0.0
    if node.kind == "binary" and node.value in "+-":
        left, right = node.children
        if (ids := dm(left)) is not None and (c := constant(right)) is not None:
            return ids[0], ids[1], c if node.value == "-" else -c
        if node.value == "+" and (ids := dm(right)) is not None:
            c = constant(left)
            if c is not None:
                return ids[0], ids[1], -c
    return None


def _contains_dm(node: Node) -> bool:
    if node.kind == "call" and node.value == "DM":
        return True
    return any(_contains_dm(c) for c in node.children)
