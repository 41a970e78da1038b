"""Arithmetic expressions in x and y for loads, read by a small parser: nothing is evaluated as code.

Grammar (``^`` is the power, right-associative and binding tighter than a unary minus)::

    expression := term (("+" | "-") term)*
    term       := unary (("*" | "/") unary)*
    unary      := ("+" | "-") unary | power
    power      := atom ("^" unary)?
    atom       := number | "x" | "y" | "pi" | function "(" expression ")" | "(" expression ")"
    function   := "sin" | "cos" | "exp" | "sqrt"

An :class:`Expression` evaluates on numpy arrays and knows its polynomial degree (None when it is
not a polynomial), so that quadrature can be exact for polynomials.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Union

import numpy as np

FUNCTIONS = {"sin": np.sin, "cos": np.cos, "exp": np.exp, "sqrt": np.sqrt}
CONSTANTS = {"pi": math.pi}
VARIABLES = ("x", "y")
_TOKEN = re.compile(r"\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_]\w*)"
                    r"|(?P<operator>[-+*/^()]))")


class ExpressionError(ValueError):
    """A syntax error; ``position`` is the 1-based character where it was found."""

    def __init__(self, message: str, position: int):
        super().__init__(f"{message} at position {position}")
        self.position = position


# A node is a number, a variable name, or (operator, operands...).
Node = Union[float, str, tuple]


@dataclass(frozen=True)
class Expression:
    """A parsed expression: ``text`` as written and its syntax tree."""

    text: str
    tree: Node
    coefficients: tuple[float, ...] | None = None  # set for a polynomial in x given by its coefficients

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Values at the points (x, y) (arrays of one shape)."""
        with np.errstate(all="ignore"):  # the caller checks finiteness and names the key
            return np.broadcast_to(_evaluate(self.tree, np.asarray(x, float), np.asarray(y, float)),
                                   np.shape(x)).astype(float)

    @property
    def degree(self) -> int | None:
        """Total polynomial degree in (x, y), or None if the expression is not a polynomial."""
        return _degree(self.tree)

    @property
    def constant(self) -> bool:
        return self.degree == 0


def parse(text: str) -> Expression:
    """Parse ``text``; raise :class:`ExpressionError` with the position of the first problem."""
    tokens = _tokenize(text)
    parser = _Parser(tokens, len(text))
    tree = parser.expression()
    if parser.peek() is not None:
        kind, value, position = parser.peek()
        raise ExpressionError(f"unexpected {value!r}", position)
    return Expression(text, tree)


def polynomial_in_x(coefficients: tuple[float, ...]) -> Expression:
    """The polynomial Σ c_j x^j (coefficients lowest degree first) as an expression."""
    tree: Node = 0.0
    for power, c in enumerate(coefficients):
        term: Node = float(c) if power == 0 else ("*", float(c), ("^", "x", float(power)))
        tree = term if tree == 0.0 else ("+", tree, term)
    text = " + ".join(f"{c!r}*x^{j}" if j else repr(c) for j, c in enumerate(coefficients)) or "0"
    return Expression(text, tree, tuple(float(c) for c in coefficients))


def constant(value: float) -> Expression:
    return polynomial_in_x((float(value),))


def _tokenize(text: str) -> list[tuple[str, str, int]]:
    tokens, position = [], 0
    while position < len(text):
        if text[position:].strip() == "":
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

    def expression(self) -> Node:
        node = self.term()
        while (operator := self.accept("+", "-")) is not None:
            node = (operator, node, self.term())
        return node

    def term(self) -> Node:
        node = self.unary()
        while (operator := self.accept("*", "/")) is not None:
            node = (operator, node, self.unary())
        return node

    def unary(self) -> Node:
        operator = self.accept("+", "-")
        if operator == "-":
            return ("neg", self.unary())
        if operator == "+":
            return self.unary()
        return self.power()

    def power(self) -> Node:
        node = self.atom()
        if self.accept("^") is not None:
            node = ("^", node, self.unary())
        return node

    def atom(self) -> Node:
        kind, value, position = self.take()
        if kind == "number":
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
                return (value, argument)
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


def _evaluate(node: Node, x: np.ndarray, y: np.ndarray):
    if isinstance(node, float):
        return node
    if isinstance(node, str):
        return x if node == "x" else y
    operator, *operands = node
    values = [_evaluate(operand, x, y) for operand in operands]
    if operator in FUNCTIONS:
        return FUNCTIONS[operator](values[0])
    if operator == "neg":
        return -values[0]
    a, b = values
    return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "^": np.power}[operator](a, b)


def _degree(node: Node) -> int | None:
    if isinstance(node, float):
        return 0
    if isinstance(node, str):
        return 1
    operator, *operands = node
    degrees = [_degree(operand) for operand in operands]
    if operator == "neg":
        return degrees[0]
    if operator in FUNCTIONS:
        return 0 if degrees[0] == 0 else None
    if None in degrees:
        return None
    a, b = degrees
    if operator in "+-":
        return max(a, b)
    if operator == "*":
        return a + b
    if operator == "/":
        return a if b == 0 else None
    # "^": a polynomial only for a constant non-negative integer exponent
    if b != 0:
        return None
    exponent = float(_evaluate(operands[1], np.zeros(1), np.zeros(1)))
    if a == 0:
        return 0
    if exponent >= 0 and exponent == int(exponent):
        return a * int(exponent)
    return None
