"""A small, safe expression language for model terms.

Terms are written over the flight signals (``alpha``, ``q_hat``, ``mach``,
``delta_p`` …, see ``aerosid.modelling.effects``) with numbers, ``+ - * / **``, unary
minus, parentheses and a whitelist of element-wise functions.  An expression is
parsed with Python's ``ast`` in ``eval`` mode and then *interpreted* node by node
here: nothing is ever compiled or executed, so attribute access, subscripts,
comprehensions, lambdas, names outside the signal list and calls outside the
whitelist are rejected with a message that says where.
"""
from __future__ import annotations

import ast
from typing import Callable, Mapping

import numpy as np

FUNCTIONS = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "arctan": np.arctan, "tanh": np.tanh,
    "exp": np.exp, "log": np.log, "sqrt": np.sqrt, "abs": np.abs, "sign": np.sign,
}
_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide, ast.Pow: np.power}
_UNARY = {ast.USub: np.negative, ast.UAdd: np.positive}
MAX_LENGTH = 500
#: Deepest expression tree accepted (nodes from the root to a leaf): a model term is a
#: short formula; a deeper tree is a mistake or an attack on the interpreter's recursion.
MAX_DEPTH = 32
#: Largest magnitude of a number written in a term, and of a constant sub-expression.
MAX_CONSTANT = 1e12


class ExpressionError(ValueError):
    """A term that is not valid in the expression language."""

    def __init__(self, expression: str, message: str, column: int | None = None):
        self.expression, self.column = expression, column
        where = f" at column {column + 1}" if column is not None else ""
        shown = expression if len(expression) <= 80 else expression[:60] + f"... ({len(expression)} characters)"
        super().__init__(f"bad term {shown!r}{where}: {message}")


def parse(expression: str, signals: set[str] | frozenset[str]) -> ast.Expression:
    """Parse and check an expression against the allowed signal names; returns the tree."""
    if not isinstance(expression, str) or not expression.strip():
        raise ExpressionError(str(expression), "empty expression")
    if len(expression) > MAX_LENGTH:
        raise ExpressionError(expression[:40] + "...", f"longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(expression.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(expression, f"syntax error ({exc.msg})", (exc.offset or 1) - 1) from None
    _check(tree.body, expression, frozenset(signals), 1)
    _fold_constants(tree.body, expression)
    return tree


def _check(node: ast.AST, text: str, signals: frozenset[str], depth: int) -> None:
    col = getattr(node, "col_offset", None)
    if depth > MAX_DEPTH:
        raise ExpressionError(text, f"nested deeper than {MAX_DEPTH} levels", col)
    depth += 1
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(text, f"only numbers are allowed as constants, not {node.value!r}", col)
        if isinstance(node.value, int) and abs(node.value) > MAX_CONSTANT:
            digits = len(str(abs(node.value))) if abs(node.value) < 10**4000 else "thousands of"
            raise ExpressionError(text, f"the number at this column has {digits} digits: numbers in a term must "
                                  f"lie within ±{MAX_CONSTANT:g}", col)
        if isinstance(node.value, float) and not (abs(node.value) <= MAX_CONSTANT):
            raise ExpressionError(text, f"the number {node.value!r} is outside ±{MAX_CONSTANT:g}", col)
    elif isinstance(node, ast.Name):
        if node.id not in signals:
            known = ", ".join(sorted(signals))
            raise ExpressionError(text, f"unknown name {node.id!r}; available signals: {known}", col)
    elif isinstance(node, ast.BinOp):
        if type(node.op) not in _BINARY:
            raise ExpressionError(text, f"operator {type(node.op).__name__} is not allowed (use + - * / **)", col)
        _check(node.left, text, signals, depth)
        _check(node.right, text, signals, depth)
    elif isinstance(node, ast.UnaryOp):
        if type(node.op) not in _UNARY:
            raise ExpressionError(text, f"operator {type(node.op).__name__} is not allowed", col)
        _check(node.operand, text, signals, depth)
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise ExpressionError(text, f"call of {name!r} is not allowed; functions: {', '.join(FUNCTIONS)}", col)
        if node.keywords or len(node.args) != 1:
            raise ExpressionError(text, f"{node.func.id}() takes exactly one argument", col)
        _check(node.args[0], text, signals, depth)
    elif isinstance(node, ast.Attribute):
        raise ExpressionError(text, "attribute access is not allowed", col)
    else:
        raise ExpressionError(text, f"{type(node).__name__} is not allowed in a term", col)


def _fold_constants(node: ast.AST, text: str):
    """Evaluate every sub-expression without a signal (after _check): it must be a
    finite number within ±MAX_CONSTANT, and no division may be by a constant zero.
    Returns the node's value, or None when it depends on a signal."""
    col = getattr(node, "col_offset", None)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return None
    if isinstance(node, ast.BinOp):
        left, right = _fold_constants(node.left, text), _fold_constants(node.right, text)
        if isinstance(node.op, ast.Div) and right == 0.0:
            raise ExpressionError(text, f"division by zero (the divisor {ast.unparse(node.right)!r} is 0)", col)
        if left is None or right is None:
            return None
        value = _constant(_BINARY[type(node.op)], text, node, left, right)
    elif isinstance(node, ast.UnaryOp):
        operand = _fold_constants(node.operand, text)
        value = None if operand is None else _constant(_UNARY[type(node.op)], text, node, operand)
    else:  # ast.Call
        arg = _fold_constants(node.args[0], text)
        value = None if arg is None else _constant(FUNCTIONS[node.func.id], text, node, arg)
    return value


def _constant(fn, text: str, node: ast.AST, *args) -> float:
    with np.errstate(all="ignore"):
        value = float(fn(*(np.float64(a) for a in args)))
    if not (abs(value) <= MAX_CONSTANT):  # also NaN
        what = "is not a number" if value != value else f"= {value:g}, outside ±{MAX_CONSTANT:g}"
        raise ExpressionError(text, f"the constant {ast.unparse(node)!r} {what}", getattr(node, "col_offset", None))
    return value


def _eval(node: ast.AST, values: Mapping[str, np.ndarray]):
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return np.asarray(values[node.id], dtype=float)
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_eval(node.left, values), _eval(node.right, values))
    if isinstance(node, ast.UnaryOp):
        return _UNARY[type(node.op)](_eval(node.operand, values))
    if isinstance(node, ast.Call):
        return FUNCTIONS[node.func.id](_eval(node.args[0], values))
    raise AssertionError(f"unchecked node {type(node).__name__}")  # parse() rejects everything else


def _closure(node: ast.AST) -> Callable:
    """_eval(node, .) as a function built once: the same operations in the same order (the same
    values), without walking the tree at every call."""
    if isinstance(node, ast.Constant):
        c = float(node.value)
        return lambda values: c
    if isinstance(node, ast.Name):
        name = node.id
        return lambda values: np.asarray(values[name], dtype=float)
    if isinstance(node, ast.BinOp):
        op, left, right = _BINARY[type(node.op)], _closure(node.left), _closure(node.right)
        return lambda values: op(left(values), right(values))
    if isinstance(node, ast.UnaryOp):
        op, operand = _UNARY[type(node.op)], _closure(node.operand)
        return lambda values: op(operand(values))
    if isinstance(node, ast.Call):
        fn, arg = FUNCTIONS[node.func.id], _closure(node.args[0])
        return lambda values: fn(arg(values))
    raise AssertionError(f"unchecked node {type(node).__name__}")  # parse() rejects everything else


def signal_names(expression: str, signals) -> frozenset[str]:
    """The signal names an expression reads (empty for a constant term)."""
    signals = frozenset(signals)
    tree = parse(expression, signals)
    return frozenset(n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id in signals)


#: Keys a signals dict may carry besides its named signals (aerosid.modelling.models.vehicle_signals
#: puts them there for band-path flight data): the flight data's band order (an
#: aerosid.identification.band_order.BandOrder, or None) and each sample's row in that flight data.
BAND_ORDER_KEY = "_band_order"
ROW_KEY = "_row"


def evaluate(expression: str, values: Mapping[str, np.ndarray], length: int | None = None,
             keep_band_order: bool = True) -> np.ndarray:
    """Evaluate an expression on named arrays; a constant expression broadcasts to `length`.

    When ``values`` carry a band order and their rows (BAND_ORDER_KEY, ROW_KEY), the result is the
    column as the band path should form it, f(x) + LP(f(x_wide)) - f(LP(x_wide))
    (aerosid.identification.band_order; LP(f(x_wide)) alone on the rows where that leaves the range
    of the term's values: guarded_column): a non-linear term low-passed after it is formed.
    keep_band_order=False: that correction is not kept for the next call (a scan's trial terms)."""
    tree = parse(expression, frozenset(values))
    with np.errstate(all="ignore"):
        out = np.asarray(_eval(tree.body, values), dtype=float)
    if out.ndim == 0:
        n = length if length is not None else len(next(iter(values.values())))
        out = np.full(n, float(out))
    band_order = values.get(BAND_ORDER_KEY)
    if band_order is not None and ROW_KEY in values:
        out = band_order.column(expression, out, values[ROW_KEY], keep_band_order)
    return out


def compile_expression(expression: str, signals) -> Callable[[Mapping[str, np.ndarray]], np.ndarray]:
    """Parse once, evaluate many times: a function of the named arrays (for loops that
    evaluate the same term at every step, e.g. a simulation).  A constant expression
    returns a 0-d array (it broadcasts)."""
    tree = parse(expression, frozenset(signals))
    body = tree.body
    # the common terms read one signal or are a constant: no arithmetic, so no error state to set
    # (the same values as the general path, several times faster in a simulation's inner loop)
    if isinstance(body, ast.Name):
        name = body.id
        return lambda values: np.asarray(values[name], dtype=float)
    if isinstance(body, ast.Constant):
        constant = np.asarray(float(body.value), dtype=float)
        constant.flags.writeable = False  # one array for every call: no caller may change it
        return lambda values: constant

    body_fn = _closure(body)

    def run(values: Mapping[str, np.ndarray]) -> np.ndarray:
        with np.errstate(all="ignore"):
            return np.asarray(body_fn(values), dtype=float)

    return run


def names_in(expression: str, signals) -> frozenset[str]:
    """The signal names an expression reads (empty for a constant term)."""
    tree = parse(expression, frozenset(signals))
    return frozenset(n.id for n in ast.walk(tree) if isinstance(n, ast.Name))
