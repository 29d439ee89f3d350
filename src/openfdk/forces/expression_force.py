"""A generalised force given as an expression of a coordinate q and its rate qdot
(OpenSim's ExpressionBasedCoordinateForce), parsed safely.

The expression is parsed with Python's ``ast`` and only these nodes are accepted:
numbers, the names ``q`` and ``qdot``, the operators + − * / and ^ (power, as OpenSim's
Lepton writes it; ``**`` too), unary minus and plus, and calls of the functions in
:data:`FUNCTIONS` (Lepton's: sin, cos, tan, asin, acos, atan, sinh, cosh, tanh, sqrt,
exp, log, abs, square, cube, recip, min, max, step). Anything else — an attribute, a
subscript, a lambda, another name — is refused naming the element; nothing in it is
ever evaluated as Python. The parsed tree is evaluated by a small interpreter over
numpy scalars.

Units: SI (q in rad or m; the force in N m or N), as OpenSim evaluates it. The slope
df/dq (for the FDK Jacobian) is a central difference with step 1e-7 (rad or m).
"""

from __future__ import annotations

import ast
import math
import warnings

from .force_laws import ForceLawError

__all__ = ["ExpressionLaw", "parse_expression", "FUNCTIONS"]

#: the functions an expression may call (Lepton's names) and their arity
FUNCTIONS = {
    "sin": (math.sin, 1), "cos": (math.cos, 1), "tan": (math.tan, 1), "asin": (math.asin, 1),
    "acos": (math.acos, 1), "atan": (math.atan, 1), "sinh": (math.sinh, 1), "cosh": (math.cosh, 1),
    "tanh": (math.tanh, 1), "sqrt": (math.sqrt, 1), "exp": (math.exp, 1), "log": (math.log, 1),
    "abs": (abs, 1), "square": (lambda x: x * x, 1), "cube": (lambda x: x * x * x, 1),
    "recip": (lambda x: 1.0 / x, 1), "min": (min, 2), "max": (max, 2), "step": (lambda x: 1.0 if x >= 0 else 0.0, 1),
}
_OPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
        ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: _power(a, b)}


def _power(a, b):
    value = a ** b
    if isinstance(value, complex):  # a negative number to a fractional power
        raise ValueError(f"({a:g})^{b:g} is not a real number")
    return value
MAX_LENGTH = 10_000


def parse_expression(text, where="expression"):
    """The checked ``ast`` tree of an expression of q and qdot (module docstring), or
    ForceLawError naming ``where`` and what is not allowed."""
    if not isinstance(text, str) or not text.strip():
        raise ForceLawError(f"{where}: expected an expression of q and qdot, got {text!r}")
    if len(text) > MAX_LENGTH:
        raise ForceLawError(f"{where}: the expression has {len(text)} characters (at most {MAX_LENGTH})")
    try:
        with warnings.catch_warnings():  # (Python's own SyntaxWarnings about literals: the error says it)
            warnings.simplefilter("ignore", SyntaxWarning)
            tree = ast.parse(text.replace("^", "**"), mode="eval")
    except SyntaxError as exc:
        raise ForceLawError(f"{where}: not an expression ({exc.msg}): {text!r}") from None
    except (RecursionError, MemoryError, ValueError):
        raise ForceLawError(f"{where}: the expression is nested too deeply") from None
    for node in ast.walk(tree):
        if isinstance(node, (ast.Expression, ast.Load, ast.operator, ast.unaryop)):
            if isinstance(node, ast.operator) and type(node) not in _OPS:
                raise ForceLawError(f"{where}: operator {type(node).__name__} is not allowed")
            if isinstance(node, ast.unaryop) and not isinstance(node, (ast.USub, ast.UAdd)):
                raise ForceLawError(f"{where}: operator {type(node).__name__} is not allowed")
            continue
        if isinstance(node, (ast.BinOp, ast.UnaryOp)):
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            continue
        if isinstance(node, ast.Name):
            if node.id not in ("q", "qdot") and node.id not in FUNCTIONS:
                raise ForceLawError(f"{where}: unknown name {node.id!r} (the variables are q and qdot)")
            continue
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS or node.keywords:
                raise ForceLawError(f"{where}: only the functions {sorted(FUNCTIONS)} may be called")
            if len(node.args) != FUNCTIONS[node.func.id][1]:
                raise ForceLawError(f"{where}: {node.func.id} takes {FUNCTIONS[node.func.id][1]} argument(s)")
            continue
        raise ForceLawError(f"{where}: {type(node).__name__} is not allowed in an expression")
    return tree


def _evaluate(node, q, qdot):
    if isinstance(node, ast.Expression):
        return _evaluate(node.body, q, qdot)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return q if node.id == "q" else qdot
    if isinstance(node, ast.UnaryOp):
        value = _evaluate(node.operand, q, qdot)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BinOp):
        return _OPS[type(node.op)](_evaluate(node.left, q, qdot), _evaluate(node.right, q, qdot))
    function = FUNCTIONS[node.func.id][0]
    return float(function(*(_evaluate(a, q, qdot) for a in node.args)))


class ExpressionLaw:
    """f(q, q̇) of an expression (module docstring). ``force(q)`` is f at q̇ = 0 (the
    elastic part), ``damping_force(q, q̇)`` the rest, so that their sum is f(q, q̇)."""

    def __init__(self, expression, unit="rad", name=""):
        self.expression, self.unit, self.name = expression, unit, name
        self.tree = parse_expression(expression, f"spring {name!r}: expression")

    def value(self, q, qdot):
        """f (N m or N) at q, q̇; ForceLawError naming the spring when it is not finite."""
        try:
            f = _evaluate(self.tree, float(q), float(qdot))
        except (ValueError, ZeroDivisionError, OverflowError, TypeError, RecursionError) as exc:
            raise FloatingPointError(f"spring {self.name!r}: expression {self.expression!r} at q = {q:g}, "
                                     f"qdot = {qdot:g}: {exc}") from None
        if not math.isfinite(f):
            raise FloatingPointError(f"spring {self.name!r}: expression {self.expression!r} is {f} at q = {q:g}, "
                                     f"qdot = {qdot:g}")
        return f

    def force(self, measure):
        return self.value(measure, 0.0)

    def dforce_dmeasure(self, measure, h=1e-7):
        return (self.value(measure + h, 0.0) - self.value(measure - h, 0.0)) / (2.0 * h)

    def damping_force(self, q, qdot):
        return self.value(q, qdot) - self.value(q, 0.0)
