"""Arithmetic expressions in x and y (and z, in 3-D) for loads, read by a small parser: nothing is evaluated as
code.

Grammar (``^`` is the power, right-associative and binding tighter than a unary minus)::

    expression := term (("+" | "-") term)*
    term       := unary (("*" | "/") unary)*
    unary      := ("+" | "-") unary | power
    power      := atom ("^" unary)?
    atom       := number | "x" | "y" | "z" | "pi" | function "(" expression ")" | "(" expression ")"
    function   := "sin" | "cos" | "exp" | "sqrt"

An :class:`Expression` evaluates on numpy arrays and knows its polynomial degree (None when it is
not a polynomial), so that quadrature can be exact for polynomials.

The parser is bounded: at most MAX_LENGTH characters, nesting (parentheses, functions, powers, signs)
at most MAX_DEPTH deep, polynomials of degree at most MAX_DEGREE, and every number and every constant
part (``1/0``, ``10^400``, ``exp(1000)``) finite; beyond these an :class:`ExpressionError` names the
position.  Sums and products are kept as flat chains, so a long sum is no deeper than one term.
"""
from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from typing import Union

import numpy as np

FUNCTIONS = {"sin": np.sin, "cos": np.cos, "exp": np.exp, "sqrt": np.sqrt}
CONSTANTS = {"pi": math.pi}
VARIABLES = ("x", "y", "z")
#: Bounds no real load meets: characters of an expression, its nesting depth, the degree of a polynomial
#: (quadrature is exact up to it; a coefficient list has at most MAX_DEGREE + 1 entries).
MAX_LENGTH = 10_000
MAX_DEPTH = 50
MAX_DEGREE = 100
_BLANK = re.compile(r"\s*\Z")
_TOKEN = re.compile(r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_]\w*)"
                    r"|(?P<operator>[-+*/^()]))")


class ExpressionError(ValueError):
    """A syntax error; ``position`` is the 1-based character where it was found."""

    def __init__(self, message: str, position: int):
        super().__init__(f"{message} at position {position}")
        self.position = position


# A node is a number, a variable name, or (operator, operands...): ("+", a, b, c, ...) is a + b + c + ...
# from left to right (a subtracted term is ("neg", t), as exact as a subtraction), ("*", a, b, ...) a product
# from left to right in which a factor ("inv", f) divides; ("neg", a), ("^", a, b) and (function, a).
Node = Union[float, str, tuple]
#: What an operator computes, for messages.
_NAMES = {"+": "the sum", "*": "the product", "neg": "the negation", "^": "the power"}


@dataclass(frozen=True)
class Expression:
    """A parsed expression: ``text`` as written and its syntax tree."""

    text: str
    tree: Node
    coefficients: tuple[float, ...] | None = None  # set for a polynomial in x given by its coefficients

    def __call__(self, x: np.ndarray, y: np.ndarray, z: np.ndarray | float = 0.0) -> np.ndarray:
        """Values at the points (x, y, z) (arrays of one shape; a plane scene lies at z = 0, and refuses z)."""
        with np.errstate(all="ignore"):  # the caller checks finiteness and names the key
            point = {"x": np.asarray(x, float), "y": np.asarray(y, float), "z": np.asarray(z, float)}
            return np.broadcast_to(_evaluate(self.tree, point), np.shape(x)).astype(float)

    @property
    def degree(self) -> int | None:
        """Total polynomial degree in (x, y, z), or None if the expression is not a polynomial."""
        return _degree(self.tree)

    @property
    def variables(self) -> set[str]:
        """The coordinates it reads."""
        found: set[str] = set()

        def visit(node: Node) -> None:
            if isinstance(node, str):
                found.add(node)
            elif isinstance(node, tuple):
                for operand in node[1:]:
                    visit(operand)
        visit(self.tree)
        return found

    @property
    def constant(self) -> bool:
        return self.degree == 0


def parse(text: str) -> Expression:
    """Parse ``text``; raise :class:`ExpressionError` with the position of the first problem."""
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"{len(text)} characters, more than the {MAX_LENGTH} an expression may have",
                              MAX_LENGTH + 1)
    tokens = _tokenize(text)
    parser = _Parser(tokens, len(text))
    tree = parser.expression()
    if parser.peek() is not None:
        kind, value, position = parser.peek()
        raise ExpressionError(f"unexpected {value!r}", position)
    expression = Expression(text, tree)
    degree = expression.degree or 0
    if degree > MAX_DEGREE:
        shown = f"{degree}" if degree < 10 ** 9 else "above 1e9"
        raise ExpressionError(f"a polynomial of degree {shown}, above the {MAX_DEGREE} that quadrature integrates "
                              "exactly", 1)
    return expression


def polynomial_in_x(coefficients: tuple[float, ...]) -> Expression:
    """The polynomial Σ c_j x^j (coefficients lowest degree first) as an expression (a zero constant term
    is left out)."""
    terms: list[Node] = [float(c) if power == 0 else ("*", float(c), ("^", "x", float(power)))
                         for power, c in enumerate(coefficients)]
    if len(terms) > 1 and terms[0] == 0.0:
        del terms[0]
    tree: Node = ("+", *terms) if len(terms) > 1 else terms[0] if terms else 0.0
    text = " + ".join(f"{c!r}*x^{j}" if j else repr(c) for j, c in enumerate(coefficients)) or "0"
    return Expression(text, tree, tuple(float(c) for c in coefficients))


def constant(value: float) -> Expression:
    return polynomial_in_x((float(value),))


def scaled(expression: Expression, factor: float) -> Expression:
    """``factor`` times ``expression`` (same degree; a polynomial keeps its coefficients, scaled)."""
    factor = float(factor)
    coefficients = None if expression.coefficients is None else tuple(factor * c for c in expression.coefficients)
    return Expression(f"{factor!r}*({expression.text})", ("*", factor, expression.tree), coefficients)


def divisors(expression: Expression) -> list[Expression]:
    """The parts of ``expression`` whose zeros may be its poles: every divisor that is not a constant and every
    base that is not a constant raised to a power that is not a constant natural number.  Sums, products and
    the functions here are finite wherever their operands are, so an expression can grow without bound only
    towards a zero of one of these."""
    found: list[Node] = []

    def visit(node: Node) -> None:
        if not isinstance(node, tuple):
            return
        operator, *operands = node
        if operator == "inv" and _degree(operands[0]) != 0:
            found.append(operands[0])
        if operator == "^" and _degree(operands[0]) != 0 and _degree(node) is None:
            found.append(operands[0])
        for operand in operands:
            visit(operand)

    visit(expression.tree)
    return [Expression(expression.text, node) for node in found]


def _tokenize(text: str) -> list[tuple[str, str, int]]:
    tokens, position = [], 0
    while position < len(text):
        if _BLANK.match(text, position):
            break
        match = _TOKEN.match(text, position)
        if match is None or match.end() == position:
            skipped = len(text[position:]) - len(text[position:].lstrip())
            raise ExpressionError(f"unexpected character {text[position + skipped]!r}", position + skipped + 1)
        kind = match.lastgroup
        value = match.group(kind)
        tokens.append((kind, value, match.start(kind) + 1))
        position = match.end()
    return tokens


class _Parser:
    def __init__(self, tokens: list[tuple[str, str, int]], length: int):
        self.tokens, self.index, self.end = tokens, 0, length + 1
        self.depth = 0  # unary() is on every path of the recursion: its nesting is the expression's

    def peek(self):
        return self.tokens[self.index] if self.index < len(self.tokens) else None

    def take(self):
        token = self.peek()
        if token is None:
            raise ExpressionError("unexpected end of expression", self.end)
        self.index += 1
        return token

    def accept(self, *operators: str) -> str | None:
        token = self.peek()
        if token is not None and token[0] == "operator" and token[1] in operators:
            self.index += 1
            return token[1]
        return None

    def taken(self) -> int:
        """The position of the token taken last."""
        return self.tokens[self.index - 1][2]

    def expression(self) -> Node:
        operands, positions = [self.term()], []
        while (operator := self.accept("+", "-")) is not None:
            position = self.taken()
            term = self.term()
            operands.append(term if operator == "+" else fold(("neg", term), position))
            positions.append(position)
        return fold_chain("+", operands, positions)

    def term(self) -> Node:
        operands, positions = [self.unary()], []
        while (operator := self.accept("*", "/")) is not None:
            positions.append(self.taken())
            factor = self.unary()
            operands.append(factor if operator == "*" else ("inv", factor))
        return fold_chain("*", operands, positions)

    def unary(self) -> Node:
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                token = self.peek()
                raise ExpressionError(f"nested more than {MAX_DEPTH} deep (parentheses, functions, powers and signs)",
                                      token[2] if token else self.end)
            operator = self.accept("+", "-")
            if operator == "-":
                position = self.taken()
                return fold(("neg", self.unary()), position)
            if operator == "+":
                return self.unary()
            return self.power()
        finally:
            self.depth -= 1

    def power(self) -> Node:
        node = self.atom()
        if self.accept("^") is not None:
            position = self.taken()
            node = fold(("^", node, self.unary()), position)
        return node

    def atom(self) -> Node:
        kind, value, position = self.take()
        if kind == "number":
            if not math.isfinite(float(value)):
                raise ExpressionError(f"the number {value} is beyond double precision (at most "
                                      f"{sys.float_info.max:.4g})", position)
            return float(value)
        if kind == "name":
            if value in VARIABLES:
                return value
            if value in CONSTANTS:
                return CONSTANTS[value]
            if value in FUNCTIONS:
                if self.accept("(") is None:
                    raise ExpressionError(f"expected '(' after {value}", position + len(value))
                argument = self.expression()
                self.close(position)
                return fold((value, argument), position)
            known = ", ".join([*VARIABLES, *CONSTANTS, *FUNCTIONS])
            raise ExpressionError(f"unknown name {value!r} (known: {known})", position)
        if value == "(":
            node = self.expression()
            self.close(position)
            return node
        raise ExpressionError(f"unexpected {value!r}", position)

    def close(self, opened: int) -> None:
        if self.accept(")") is None:
            token = self.peek()
            raise ExpressionError(f"missing ')' for the '(' at position {opened}",
                                  token[2] if token else self.end)


def _constant(node: Node) -> bool:
    return isinstance(node, float) or (isinstance(node, tuple) and node[0] == "inv" and isinstance(node[1], float))


def fold(node: tuple, position: int) -> Node:
    """``node`` as a number if its operands are numbers; ExpressionError at ``position`` if that is not finite."""
    if not all(_constant(operand) for operand in node[1:]):
        return node
    with np.errstate(all="ignore"):
        value = float(_evaluate(node, dict.fromkeys(VARIABLES, np.zeros(()))))
    if not math.isfinite(value):
        name = "the quotient" if not isinstance(node[-1], float) else _NAMES.get(node[0], f"{node[0]}(...)")
        raise ExpressionError(f"{name} of constants gives {value} (an overflow, a division by zero or a value "
                              "outside a function's domain)", position)
    return value


def fold_chain(operator: str, operands: list[Node], positions: list[int]) -> Node:
    """The chain (operator, *operands), or the operand alone, or its value if every operand is a number
    (evaluated from left to right, the operator at ``positions[i]`` joining operand i + 1)."""
    if len(operands) == 1:
        return operands[0]
    if not all(_constant(operand) for operand in operands):
        return (operator, *operands)
    value = operands[0]
    for operand, position in zip(operands[1:], positions):
        value = fold((operator, value, operand), position)
    return value


def _evaluate(node: Node, point: dict[str, np.ndarray]):
    if isinstance(node, float):
        return node
    if isinstance(node, str):
        return point[node]
    operator, *operands = node
    if operator == "+":
        value = _evaluate(operands[0], point)
        for operand in operands[1:]:
            value = np.add(value, _evaluate(operand, point))
        return value
    if operator == "*":
        value = _evaluate(operands[0], point)
        for operand in operands[1:]:
            if isinstance(operand, tuple) and operand[0] == "inv":
                value = np.true_divide(value, _evaluate(operand[1], point))
            else:
                value = np.multiply(value, _evaluate(operand, point))
        return value
    values = [_evaluate(operand, point) for operand in operands]
    if operator in FUNCTIONS:
        return FUNCTIONS[operator](values[0])
    if operator == "neg":
        return -values[0]
    return np.power(*values)


def _degree(node: Node) -> int | None:
    if isinstance(node, float):
        return 0
    if isinstance(node, str):
        return 1
    operator, *operands = node
    degrees = [_degree(operand) for operand in operands]
    if operator == "neg":
        return degrees[0]
    if operator in FUNCTIONS or operator == "inv":
        return 0 if degrees[0] == 0 else None
    if None in degrees:
        return None
    if operator == "+":
        return max(degrees)
    if operator == "*":
        return sum(degrees)
    # "^": a polynomial only for a constant non-negative integer exponent
    a, b = degrees
    if b != 0:
        return None
    exponent = float(_evaluate(operands[1], dict.fromkeys(VARIABLES, np.zeros(1))))
    if a == 0:
        return 0
    if exponent >= 0 and exponent == int(exponent):
        return a * int(exponent)
    return None
