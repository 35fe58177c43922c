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
#: The budget of an expression, checked before anything is computed: its text (so also the
#: digits of a literal) and its syntax tree (so the number of operations) ...
MAX_TEXT = 1000
MAX_NODES = 200
#: ... and every operation's result, estimated from its operands before it is computed:
#: integers of at most this many bits (about 3000 digits: Python prints up to 4300), so that
#: nested powers (``2 ** 2 ** 2 ** 2 ** 2``) or ``(10 ** 1000) ** 1000`` are refused instead
#: of computed, ...
MAX_INT_BITS = 10_000
#: ... and lists of at most this many numbers in all (nested lists counted in full), so that
#: ``[1] * 10 ** 9`` is refused instead of filling the memory. A box or a list of positions of
#: many agents is far below.
MAX_ITEMS = 100_000
#: Largest number of digits ``round(x, n)`` accepts (``round(x, -10 ** 9)`` computes 10^n).
MAX_ROUND_DIGITS = 1000


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
        if len(text) > MAX_TEXT:
            raise ExpressionError(f'{len(text)} characters: an expression has at most '
                                  f'{MAX_TEXT}')
        try:
            tree = ast.parse(text.strip(), mode='eval')
        except SyntaxError as exc:
            raise ExpressionError(f'invalid syntax in {text!r}: {exc.msg}') from None
        except ValueError as exc:  # a literal Python refuses to convert (too many digits)
            raise ExpressionError(f'{text!r}: {exc}') from None
        nodes = sum(1 for _ in ast.walk(tree.body))
        if nodes > MAX_NODES:
            raise ExpressionError(f'{text!r}: {nodes} operations and operands: an expression '
                                  f'has at most {MAX_NODES}')
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
            self._budget(node.op, left, right)
            return _BINARY[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp):
            return _UNARY[type(node.op)](self._eval(node.operand, values))
        if isinstance(node, ast.List):
            out = [self._eval(item, values) for item in node.elts]
            self._fits(_items(out))
            return out
        if isinstance(node, ast.Call):
            args = [self._eval(a, values) for a in node.args]
            if node.func.id == 'round' and len(args) > 1 and isinstance(args[1], int) \
                    and abs(args[1]) > MAX_ROUND_DIGITS:
                raise ExpressionError(f'{self.text!r}: round to {args[1]} digits: at most '
                                      f'{MAX_ROUND_DIGITS}')
            return FUNCTIONS[node.func.id](*args)
        name = _dotted(node, self.text)
        if name in values:
            return values[name]
        if name in CONSTANTS:
            return CONSTANTS[name]
        raise ExpressionError(f'{self.text!r}: unknown name {name!r} (known: '
                              f'{", ".join(sorted(values)) or "none"})')

    def _budget(self, op: ast.operator, left: Any, right: Any) -> None:
        """Refuse an operation whose result would exceed the budget, before computing it."""
        if isinstance(op, ast.Pow) and _integer(left) and _integer(right) and right > 0:
            # |a ** b| < 2 ** (b * bits(a)); the product is computed from the bit counts.
            self._bits(left.bit_length() * right)
        elif isinstance(op, ast.Mult):
            if _integer(left) and _integer(right):
                self._bits(left.bit_length() + right.bit_length())
            elif isinstance(left, list) and _integer(right):
                self._fits(_items(left) * max(right, 0))
            elif _integer(left) and isinstance(right, list):
                self._fits(_items(right) * max(left, 0))
        elif isinstance(op, ast.Add) and isinstance(left, list) and isinstance(right, list):
            self._fits(_items(left) + _items(right))

    def _bits(self, bits: int) -> None:
        """Refuse an integer result of about ``bits`` bits beyond :data:`MAX_INT_BITS`."""
        if bits > MAX_INT_BITS:
            raise ExpressionError(f'{self.text!r}: an integer of about {bits} bits: the '
                                  f'budget of an expression is {MAX_INT_BITS} bits')

    def _fits(self, items: int) -> None:
        """Refuse a list result of ``items`` numbers beyond :data:`MAX_ITEMS`."""
        if items > MAX_ITEMS:
            raise ExpressionError(f'{self.text!r}: a list of {items} numbers: the budget of '
                                  f'an expression is {MAX_ITEMS}')


def _integer(value: Any) -> bool:
    """Return whether ``value`` is an integer (a bool counts as one, as in Python)."""
    return isinstance(value, int)


def _items(value: Any) -> int:
    """Return how many numbers a (nested) list holds, each shared sublist counted in full.

    Only lists within the budget exist, so this costs at most :data:`MAX_ITEMS` steps.
    """
    if isinstance(value, list):
        return sum(_items(v) for v in value) if value else 0
    return 1


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
