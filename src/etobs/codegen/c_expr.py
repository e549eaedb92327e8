"""etobs' scalar formulas (:mod:`etobs.formulas`) as C expressions, read from their Python source.

A rule's or K-function's formula is a function whose body is one ``return`` of an
arithmetic expression (or an annotated assignment, then its return). It is translated
node by node, fully parenthesized, so the C computes the same operations in the same
order as Python does: ``a + b * c`` stays ``(a + (b * c))``, ``s**k`` becomes
``pow(s, k)``. Numbers are written as hexadecimal floating constants, exact in the
``float64`` profile. Anything else (a call, a comparison, a name that is not a
parameter) is refused, naming the formula: the generator does not guess.
"""

from __future__ import annotations

import ast
import functools
import inspect
import textwrap
from collections.abc import Callable, Sequence
from typing import Any

from etobs.errors import InputError

#: The C types and functions of each profile: the real type, its literal suffix, sqrt, pow.
PROFILES: dict[str, dict[str, str]] = {
    "float64": {"real": "double", "suffix": "", "sqrt": "sqrt", "pow": "pow"},
    "float32": {"real": "float", "suffix": "f", "sqrt": "sqrtf", "pow": "powf"},
}


def literal(x: float, profile: str) -> str:
    """``x`` as a C floating constant of ``profile``: hexadecimal, exact for a double."""
    x = float(x)
    if x != x or x in (float("inf"), float("-inf")):
        raise InputError(f"a number of the rule is {x!r}; the generated C takes finite numbers only")
    text = x.hex()
    suffix = PROFILES[profile]["suffix"]
    return f"({text}{suffix})" if x < 0 else f"{text}{suffix}"


@functools.cache
def _expression(fn: Callable[..., Any]) -> tuple[tuple[str, ...], ast.expr]:
    """The parameters of ``fn`` and the expression it returns."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    func = tree.body[0]
    assert isinstance(func, ast.FunctionDef)
    params = tuple(a.arg for a in func.args.args)
    body = [s for s in func.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    names: dict[str, ast.expr] = {}
    for stmt in body[:-1]:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None:
            names[stmt.target.id] = stmt.value
        else:
            raise InputError(f"{fn.__name__}: only `name: T = expression` and `return` can be written as C")
    last = body[-1]
    if not isinstance(last, ast.Return) or last.value is None:
        raise InputError(f"{fn.__name__}: the last statement must return an expression to be written as C")
    value = last.value
    if isinstance(value, ast.Name) and value.id in names:
        value = names[value.id]
    return params, value


def c_expression(fn: Callable[..., Any], args: Sequence[str], profile: str) -> str:
    """``fn(*args)`` as a C expression; ``args`` are C expressions, one per parameter of ``fn``."""
    params, expr = _expression(fn)
    if len(args) != len(params):
        raise InputError(f"{fn.__name__} takes {len(params)} arguments; got {len(args)}")
    bound = dict(zip(params, args, strict=True))
    pw = PROFILES[profile]["pow"]

    def emit(node: ast.expr) -> str:
        if isinstance(node, ast.BinOp):
            a, b = emit(node.left), emit(node.right)
            ops = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
            if isinstance(node.op, ast.Pow):
                return f"{pw}({a}, {b})"
            if type(node.op) in ops:
                return f"({a} {ops[type(node.op)]} {b})"
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return f"(-{emit(node.operand)})"
        elif isinstance(node, ast.Name) and node.id in bound:
            return bound[node.id]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, int | float)
            and not isinstance(node.value, bool)
        ):
            return literal(float(node.value), profile)
        raise InputError(f"{fn.__name__}: `{ast.unparse(node)}` cannot be written as C by etobs codegen")

    return emit(expr)
