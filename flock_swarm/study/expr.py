"""The small, safe expression language of a sweep's derived values.

A derived value is computed from the axis values of one point, for example Su, Wang, Lin 2009
Section V.A's box side ``sqrt(n_agents / 0.05)``. The text is parsed with :mod:`ast` and only
these nodes are evaluated: numbers, names of axes (a dotted scenario path such as
``informed.fraction`` reads as attribute access), ``+ - * / // % **``, unary ``-`` and ``+``,
list literals (a box is ``[[0.0, L], [0.0, L]]``) and calls of the functions in
:data:`FUNCTIONS`. Anything else (attributes of values, subscripts, comprehensions, keywords,
strings, lambdas ...) is rejected when the spec is read, before any run; Python's ``eval`` is
never used.
"""

import ast
import math
import operator
from typing import Any, Callable

#: The functions an expression may call.
FUNCTIONS: dict[str, Callable[..., Any]] = {
    'sqrt': math.sqrt, 'exp': math.exp, 'log': math.log, 'log10': math.log10,
    'sin': math.sin, 'cos': math.cos, 'floor': math.floor, 'ceil': math.ceil,
    'abs': abs, 'round': round, 'int': int, 'float': float, 'min': min, 'max': max,
}
#: Constants an expression may name.
CONSTANTS = {'pi': math.pi}
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod,
           ast.Pow: operator.pow}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
#: Largest exponent ``**`` accepts: keeps a typo from computing a number of a million digits.
MAX_EXPONENT = 1000


class ExpressionError(ValueError):
    """An expression that is not in the language, or that fails on a point's values."""


class Expression:
    """A parsed expression: :meth:`names` it reads and :meth:`evaluate` on a point."""

    def __init__(self, text: str) -> None:
        """Parse and check ``text``.

        :param text: the expression, e.g. ``sqrt(n_agents / 0.05)``.
        :raises ExpressionError: on a syntax error or a construct outside the language.
        """
        self.text = text
        try:
            tree = ast.parse(text.strip(), mode='eval')
        except SyntaxError as exc:
            raise ExpressionError(f'invalid syntax in {text!r}: {exc.msg}') from None
        self._tree = tree.body
        self._names: set[str] = set()
        self._check(self._tree)

    def names(self) -> set[str]:
        """Return the (dotted) names the expression reads."""
        return set(self._names)

    def _check(self, node: ast.AST) -> None:
        """Reject anything outside the language; collect the names read."""
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise ExpressionError(f'{self.text!r}: only numbers are allowed, '
                                      f'not {node.value!r}')
        elif isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            self._check(node.left)
            self._check(node.right)
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            self._check(node.operand)
        elif isinstance(node, ast.List):
            for item in node.elts:
                self._check(item)
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                raise ExpressionError(f'{self.text!r}: unknown function '
                                      f'{ast.unparse(node.func)!r} (allowed: '
                                      f'{", ".join(sorted(FUNCTIONS))})')
            if node.keywords:
                raise ExpressionError(f'{self.text!r}: keyword arguments are not allowed')
            for arg in node.args:
                self._check(arg)
        elif isinstance(node, (ast.Name, ast.Attribute)):
            self._names.add(_dotted(node, self.text))
        else:
            raise ExpressionError(f'{self.text!r}: {ast.unparse(node)!r} is not allowed '
                                  '(numbers, names, + - * / // % **, lists and '
                                  'function calls only)')

    def evaluate(self, values: dict[str, Any]) -> Any:
        """Return the expression's value at a point.

        :param values: the axis (and earlier derived) values by dotted name.
        :return: a number or a (nested) list of numbers.
        :raises ExpressionError: on an unknown name or a failing operation (``sqrt(-1)``,
            a division by zero ...).
        """
        try:
            return self._eval(self._tree, values)
        except ExpressionError:
            raise
        except (ArithmeticError, ValueError, TypeError) as exc:
            raise ExpressionError(f'{self.text!r} fails at {_point(values)}: {exc}') from None

    def _eval(self, node: ast.AST, values: dict[str, Any]) -> Any:
        """Evaluate a node already checked by :meth:`_check`."""
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.BinOp):
            left, right = self._eval(node.left, values), self._eval(node.right, values)
            if isinstance(node.op, ast.Pow) and isinstance(right, (int, float)) \
                    and abs(right) > MAX_EXPONENT:
                raise ExpressionError(f'{self.text!r}: exponent {right} is larger than '
                                      f'{MAX_EXPONENT}')
            return _BINARY[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp):
            return _UNARY[type(node.op)](self._eval(node.operand, values))
        if isinstance(node, ast.List):
            return [self._eval(item, values) for item in node.elts]
        if isinstance(node, ast.Call):
            return FUNCTIONS[node.func.id](*(self._eval(a, values) for a in node.args))
        name = _dotted(node, self.text)
        if name in values:
            return values[name]
        if name in CONSTANTS:
            return CONSTANTS[name]
        raise ExpressionError(f'{self.text!r}: unknown name {name!r} (known: '
                              f'{", ".join(sorted(values)) or "none"})')


def _dotted(node: ast.AST, text: str) -> str:
    """Return the dotted name of ``a`` or ``a.b.c``."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        raise ExpressionError(f'{text!r}: {ast.unparse(node)!r} is not allowed')
    parts.append(node.id)
    return '.'.join(reversed(parts))


def _point(values: dict[str, Any]) -> str:
    """Return a point's values as ``a=1, b=2``."""
    return ', '.join(f'{k}={v!r}' for k, v in values.items()) or 'no axes'
