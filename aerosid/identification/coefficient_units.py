"""Per radian or per degree: the unit of a coefficient from its term's expression.

Inside aerosid every coefficient is SI per radian: it multiplies its term evaluated
with angles in radians and rates in rad/s.  A coefficient whose term is a power k of
angles (``alpha`` k = 1, ``alpha*abs(alpha)`` k = 2, ``delta_p/2`` k = 1 — per radian
of δ/2, the seed's "per degree pair" —, ``q_hat`` k = 1, ``alpha*(mach - 12.4)``
k = 1, ``alpha_r**2*sin(4*phi_r)`` k = 2: a function such as sin of the physical angle
is a number whatever unit the angle is written in) is per radian^k, and per degree^k it
is ``estimate * (pi/180)**k``.  A term without an angle unit (``cos(4*phi_r)``, a
constant, ``mach - 12.4``) has a coefficient per unit of term, the same in both.
"""
from __future__ import annotations

import ast
import math

#: Signals in radians or rad/s (the rest — mach, V, qbar, t — carry no angle).
ANGLE_SIGNALS = frozenset({"alpha", "beta", "alpha_r", "phi_r", "delta_p", "delta_y", "delta_r", "p", "q", "r",
                           "p_hat", "q_hat", "r_hat", "alpha_dot_hat", "beta_dot_hat"})
DEG = math.pi / 180.0


def angle_power(expression: str) -> float | None:
    """The power k of the angle unit in a term (rad^k), or None when the term mixes powers
    (alpha + mach)."""
    try:
        tree = ast.parse(expression.strip(), mode="eval")
    except SyntaxError:
        return None
    return _power(tree.body)


def _const(node: ast.AST) -> float | None:
    try:
        value = ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return None
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _power(node: ast.AST) -> float | None:
    if isinstance(node, ast.Constant):
        return 0.0
    if isinstance(node, ast.Name):
        return 1.0 if node.id in ANGLE_SIGNALS else 0.0
    if isinstance(node, ast.UnaryOp):
        return _power(node.operand)
    if isinstance(node, ast.BinOp):
        left = _power(node.left)
        if isinstance(node.op, ast.Pow):
            exponent = _const(node.right)
            if left is None:
                return None
            if left == 0.0:
                return 0.0 if _power(node.right) == 0.0 else None
            return left * exponent if exponent is not None else None
        right = _power(node.right)
        if left is None or right is None:
            return None
        if isinstance(node.op, ast.Mult):
            return left + right
        if isinstance(node.op, ast.Div):
            return left - right
        return left if left == right else None  # + and -: both sides of one power
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and len(node.args) == 1:
        arg = _power(node.args[0])
        if node.func.id not in ("abs", "sqrt", "sign"):
            return 0.0
        if arg is None:
            return None
        if node.func.id == "abs":
            return arg
        if node.func.id == "sign":
            return 0.0
        if node.func.id == "sqrt":
            return arg / 2.0
        return 0.0  # sin, cos, exp ... of the physical angle: a number, whatever unit the angle is written in
    return None


def per_degree_factor(expression: str) -> float:
    """Multiply a per-radian coefficient of this term by this to get it per degree
    ((pi/180)^k; 1 for a term that is not a power of angles)."""
    k = angle_power(expression)
    return DEG ** k if k else 1.0


def unit_label(expression: str, per_degree: bool) -> str:
    """'/rad', '/rad^2', '/deg', ... or '' for a coefficient per unit of its term."""
    k = angle_power(expression)
    if not k:
        return ""
    base = "/deg" if per_degree else "/rad"
    return base if k == 1 else f"{base}^{k:g}"


def units_header(per_degree: bool) -> str:
    """The one line that says which units a coefficient table is in."""
    if per_degree:
        return ("PER DEGREE (--per-degree): angle and control slopes per deg (a finned vehicle's fin slopes per "
                "degree pair, i.e. of delta/2), rate derivatives per deg/s")
    return ("SI per radian: angle and control slopes per rad (a finned vehicle's fin slopes per rad of delta/2), "
            "rate derivatives per rad/s")
