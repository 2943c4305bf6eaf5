"""BT.CPP's scripting language: parsing and evaluation against a blackboard.

Scripts appear in `Script code="..."`, `ScriptCondition`, `Precondition if="..."` and the pre- and
post-condition attributes (`_skipIf`, `_onSuccess`, ...). A script is a `;`-separated list of
expressions; its value is the value of the last one. The grammar, from loosest to tightest:

    assignment   a := e, a = e, a += e, a -= e, a *= e, a /= e    (not chained)
    conditional  c ? e : e                                          (not chained)
    logical      || &&                  (one level, left to right)
    comparison   == != < > <= >=        (chained: a < b < c)
    group        one of: math (+ - * /, unary -), bit operations (& | ^, unary ~ and !), or
                 string concatenation (a .. b .. c); mixing groups needs parentheses
    atom         ( e ), true, false, names (a key, `@key` for the root blackboard, or an enum),
                 'text' or "text", integers (also 0x1F), reals (1.5, 2e3)

Evaluation follows BT.CPP 4.8: every arithmetic, comparison and logical result is a double;
`true`/`false` are the integers 1/0; `:=` creates an entry, `=` needs it to exist; assigning keeps
the type of an existing entry (an int stays an int, a string into a typed entry is parsed); `..`
joins strings and numbers (numbers printed as C++ does, a double with six decimals).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Final

from twin.bt.blackboard import Blackboard
from twin.bt.values import ConversionError, PortType, cast_value, copy_into, stod_out_of_range, value_to_string
from twin.core.errors import TreeError

__all__ = ["Environment", "Script", "ScriptError", "ScriptSyntaxError", "parse_script", "script_truth"]


class ScriptSyntaxError(TreeError):
    """A script does not parse.

    Attributes:
        column: 1-based column of the problem in the script text.
        problem: what is wrong.
    """

    def __init__(self, text: str, column: int, problem: str) -> None:
        self.text = text
        self.column = column
        self.problem = problem
        super().__init__(f"script syntax error at column {column}: {problem} in [{text}]")


class ScriptError(TreeError):
    """A script failed while it ran (missing variable, type mismatch, ...)."""


class Environment:
    """What a script runs against: a blackboard and the scripting enums of the factory."""

    __slots__ = ("blackboard", "enums")

    def __init__(self, blackboard: Blackboard, enums: Mapping[str, int]) -> None:
        self.blackboard = blackboard
        self.enums = enums


# -- tokens ------------------------------------------------------------------------------------

_OPERATORS: Final = (
    ":=", "==", "!=", "<=", ">=", "+=", "-=", "*=", "/=", "&&", "||", "..",
    "+", "-", "*", "/", "&", "|", "^", "~", "!", "<", ">", "=", "?", ":", "(", ")", ";",
)  # fmt: skip
_ASSIGN_OPS: Final = frozenset((":=", "=", "+=", "-=", "*=", "/="))
_COMPARE_OPS: Final = frozenset(("==", "!=", "<", ">", "<=", ">="))
_ARITHMETIC_OPS: Final = frozenset(("+", "-", "*", "/"))
_BIT_OPS: Final = frozenset(("&", "|", "^"))
# The group of each operator that belongs to one (`~` and `!` are bit operators in BT.CPP's grammar).
_GROUP_OF: Final = {
    **dict.fromkeys(_ARITHMETIC_OPS, "math"),
    **dict.fromkeys((*_BIT_OPS, "~", "!"), "bit"),
    "..": "string",
}
_INT64_MAX: Final = 2**63 - 1

_OP, _NAME, _NUMBER, _STRING, _BOOL, _END = range(6)


class _Token:
    __slots__ = ("kind", "pos", "text", "value")

    def __init__(self, kind: int, text: str, pos: int, value: Any = None) -> None:
        self.kind = kind
        self.text = text
        self.pos = pos
        self.value = value


def _is_name_start(ch: str) -> bool:
    return ch in {"_", "@"} or ch.isidentifier()


def _is_name_continue(ch: str) -> bool:
    return ch == "_" or ch.isdigit() or ("a" + ch).isidentifier()


def _tokenize(text: str) -> list[_Token]:
    tokens: list[_Token] = []
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in " \t\r\n":
            i += 1
            continue
        if ch == "\\" and text[i + 1 : i + 2] == "\n":
            i += 2
            continue
        if ch in _DIGITS:  # ASCII digits only: '²' is no number in BT.CPP's grammar
            i = _number(text, i, tokens)
            continue
        if ch in "'\"":
            end = text.find(ch, i + 1)
            if end < 0:
                raise ScriptSyntaxError(text, i + 1, "missing closing quote")
            wide = next((k for k in range(i + 1, end) if ord(text[k]) > 127), None)
            if wide is not None:  # BT.CPP's grammar reads a string literal as ASCII characters only
                raise ScriptSyntaxError(text, wide + 1, f"non-ASCII character {text[wide]!r} in a string literal")
            tokens.append(_Token(_STRING, text[i : end + 1], i, text[i + 1 : end]))
            i = end + 1
            continue
        if _is_name_start(ch):
            j = i + 1
            while j < n and _is_name_continue(text[j]):
                j += 1
            word = text[i:j]
            for literal, value in (("true", 1), ("false", 0)):
                if word.startswith(literal):
                    if len(word) > len(literal):
                        # BT.CPP reads the boolean literal first and then chokes on the rest.
                        raise ScriptSyntaxError(text, i + len(literal) + 1, f"unexpected {word[len(literal)]!r}")
                    tokens.append(_Token(_BOOL, word, i, value))
                    break
            else:
                tokens.append(_Token(_NAME, word, i, word))
            i = j
            continue
        for op in _OPERATORS:
            if text.startswith(op, i):
                tokens.append(_Token(_OP, op, i))
                i += len(op)
                break
        else:
            raise ScriptSyntaxError(text, i + 1, f"unexpected character {ch!r}")
    tokens.append(_Token(_END, "", n))
    return tokens


_DIGITS: Final = frozenset("0123456789")


def _number(text: str, i: int, tokens: list[_Token]) -> int:
    """Read an integer or real literal at `i`; return the index after it."""
    n = len(text)
    start = i
    if text.startswith(("0x", "0X"), i) and i + 2 < n and text[i + 2] in "0123456789abcdefABCDEF":
        j = i + 2
        while j < n and text[j] in "0123456789abcdefABCDEF":
            j += 1
        value: Any = int(text[i + 2 : j], 16)
        is_real = False
    else:
        j = i
        while j < n and text[j] in _DIGITS:
            j += 1
        is_real = False
        if j < n and text[j] == "." and j + 1 < n and text[j + 1] in _DIGITS:
            is_real = True
            j += 1
            while j < n and text[j] in _DIGITS:
                j += 1
        if j < n and text[j] in "eE":
            k = j + 1
            if k < n and text[k] in "+-":
                k += 1
            if k < n and text[k] in _DIGITS:
                is_real = True
                j = k
                while j < n and text[j] in _DIGITS:
                    j += 1
        value = float(text[start:j]) if is_real else int(text[start:j])
    if j < n and (text[j] == "." or text[j] == "_" or text[j].isalpha()):
        kind = "double" if is_real else "integer"
        raise ScriptSyntaxError(text, j + 1, f"invalid suffix on {kind} literal")
    if not is_real and value > _INT64_MAX:
        raise ScriptSyntaxError(text, start + 1, "integer literal out of range")
    if is_real and stod_out_of_range(text[start:j], value):  # BT.CPP reads it with std::stod, which throws
        raise ScriptSyntaxError(text, start + 1, "double literal out of range")
    tokens.append(_Token(_NUMBER, text[start:j], start, value))
    return j


# -- AST ---------------------------------------------------------------------------------------


class _Expr:
    __slots__ = ()

    def evaluate(self, env: Environment) -> Any:
        raise NotImplementedError


class _Literal(_Expr):
    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value

    def evaluate(self, env: Environment) -> Any:
        return self.value


class _Name(_Expr):
    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def evaluate(self, env: Environment) -> Any:
        enum_value = env.enums.get(self.name)
        if enum_value is not None:
            return float(enum_value)
        entry = env.blackboard.get_entry(self.name)
        if entry is None:
            msg = f"Variable not found: {self.name}"
            raise ScriptError(msg)
        return entry.value


def _to_double(value: Any) -> float:
    return float(cast_value(value, PortType.DOUBLE))


def _is_num(value: Any) -> bool:
    return isinstance(value, int | float)


class _Unary(_Expr):
    __slots__ = ("op", "operand")

    def __init__(self, op: str, operand: _Expr) -> None:
        self.op = op
        self.operand = operand

    def evaluate(self, env: Environment) -> Any:
        value = self.operand.evaluate(env)
        if _is_num(value):
            number = _to_double(value)
            if self.op == "-":
                return -number
            if self.op == "~":
                if math.isnan(number):
                    return float(~(-(2**63)))  # what C++ gives for (int64_t)NaN on x86-64
                if not -(2**63) <= number <= _INT64_MAX:
                    msg = "Number out of range for bitwise operation"
                    raise ScriptError(msg)
                return float(~int(number))
            return float(not number)
        if isinstance(value, str):
            msg = "Invalid operator for std::string"
            raise ScriptError(msg)
        msg = f"the operand of the operator [{self.op}] is not initialized"
        raise ScriptError(msg)


def _require_operands(op: str, lhs: Any, rhs: Any) -> None:
    for side, value in (("left", lhs), ("right", rhs)):
        if value is None:
            msg = f"The {side} operand of the operator [{op}] is not initialized"
            raise ScriptError(msg)


def _divide(lhs: float, rhs: float) -> float:
    try:
        return lhs / rhs
    except ZeroDivisionError:
        if lhs == 0.0 or math.isnan(lhs):
            return math.nan
        return math.copysign(math.inf, lhs) * math.copysign(1.0, rhs)


class _Binary(_Expr):
    __slots__ = ("lhs", "op", "rhs")

    def __init__(self, lhs: _Expr, op: str, rhs: _Expr) -> None:
        self.lhs = lhs
        self.op = op
        self.rhs = rhs

    def evaluate(self, env: Environment) -> Any:
        op = self.op
        lhs = self.lhs.evaluate(env)
        rhs = self.rhs.evaluate(env)
        _require_operands(op, lhs, rhs)
        if _is_num(lhs) and _is_num(rhs):
            if op == "+":
                return _to_double(lhs) + _to_double(rhs)
            if op == "-":
                return _to_double(lhs) - _to_double(rhs)
            if op == "*":
                return _to_double(lhs) * _to_double(rhs)
            if op == "/":
                return _divide(_to_double(lhs), _to_double(rhs))
            if op in _BIT_OPS:
                try:
                    left = int(cast_value(lhs, PortType.INT64))
                    right = int(cast_value(rhs, PortType.INT64))
                except ConversionError:
                    msg = "Binary operators are not allowed if one of the operands is not an integer"
                    raise ScriptError(msg) from None
                if op == "&":
                    return float(left & right)
                return float(left | right) if op == "|" else float(left ^ right)
            if op in ("&&", "||"):
                try:
                    left_b = cast_value(lhs, PortType.BOOL)
                    right_b = cast_value(rhs, PortType.BOOL)
                except ConversionError:
                    msg = "Logic operators are not allowed if one of the operands is not castable to bool"
                    raise ScriptError(msg) from None
                return float(left_b and right_b) if op == "&&" else float(left_b or right_b)
            # `..` of two numbers yields an empty value in BT.CPP 4.8.
            return None
        if isinstance(lhs, str) and isinstance(rhs, str) and op == "+":
            return lhs + rhs
        printable = (_is_num(lhs) or isinstance(lhs, str)) and (_is_num(rhs) or isinstance(rhs, str))
        if op == ".." and printable and (isinstance(lhs, str) or isinstance(rhs, str)):
            return value_to_string(lhs) + value_to_string(rhs)
        msg = f"Operation not permitted: [{op}] between {type(lhs).__name__} and {type(rhs).__name__}"
        raise ScriptError(msg)


def _string_to_double(text: str, env: Environment) -> float:
    """A string as a number for comparisons: `true`/`false`, an enum name, or a numeric prefix."""
    if text == "true":
        return 1.0
    if text == "false":
        return 0.0
    enum_value = env.enums.get(text)
    if enum_value is not None:
        return float(enum_value)
    try:
        return _to_double(text)
    except ConversionError as err:
        msg = f"cannot compare [{text}] with a number: {err}"
        raise ScriptError(msg) from None


_EPSILON: Final = 1.1920928955078125e-07  # float epsilon, BT.CPP's tolerance for ==


def _compare(op: str, lhs: Any, rhs: Any) -> bool:
    # Written as BT.CPP writes them (a negated test), which matters for NaN: every ordering holds.
    if op == "==":
        return abs(lhs - rhs) <= _EPSILON if isinstance(lhs, float) else bool(lhs == rhs)
    if op == "!=":
        return not (abs(lhs - rhs) <= _EPSILON) if isinstance(lhs, float) else bool(lhs != rhs)
    if op == "<":
        return not lhs >= rhs
    if op == ">":
        return not lhs <= rhs
    if op == "<=":
        return not lhs > rhs
    return not lhs < rhs


class _Compare(_Expr):
    __slots__ = ("operands", "ops")

    def __init__(self, ops: list[str], operands: list[_Expr]) -> None:
        self.ops = ops
        self.operands = operands

    def evaluate(self, env: Environment) -> Any:
        lhs = self.operands[0].evaluate(env)
        for index, op in enumerate(self.ops):
            rhs = self.operands[index + 1].evaluate(env)
            _require_operands(op, lhs, rhs)
            lhs_num, rhs_num = _is_num(lhs), _is_num(rhs)
            if lhs_num and rhs_num:
                result = _compare(op, _to_double(lhs), _to_double(rhs))
            elif isinstance(lhs, str) and isinstance(rhs, str):
                result = _compare(op, lhs, rhs)
            elif isinstance(lhs, str) and rhs_num:
                result = _compare(op, _string_to_double(lhs, env), _to_double(rhs))
            elif lhs_num and isinstance(rhs, str):
                result = _compare(op, _to_double(lhs), _string_to_double(rhs, env))
            else:
                msg = (
                    f"Can't mix different types in Comparison. Left operand [{type(lhs).__name__}] "
                    f"right operand [{type(rhs).__name__}]"
                )
                raise ScriptError(msg)
            if not result:
                return 0.0
            lhs = rhs
        return 1.0


class _If(_Expr):
    __slots__ = ("condition", "else_", "then")

    def __init__(self, condition: _Expr, then: _Expr, else_: _Expr) -> None:
        self.condition = condition
        self.then = then
        self.else_ = else_

    def evaluate(self, env: Environment) -> Any:
        value = self.condition.evaluate(env)
        try:
            # BT.CPP casts the condition to double, also a string (which must then be numeric).
            truth = _to_double(value) != 0.0
        except ConversionError as err:
            msg = f"the condition of [?:] is not a number: {err}"
            raise ScriptError(msg) from None
        return self.then.evaluate(env) if truth else self.else_.evaluate(env)


class _Assign(_Expr):
    __slots__ = ("lhs", "op", "rhs")

    def __init__(self, lhs: _Expr, op: str, rhs: _Expr) -> None:
        self.lhs = lhs
        self.op = op
        self.rhs = rhs

    def evaluate(self, env: Environment) -> Any:
        if not isinstance(self.lhs, _Name):
            msg = "Assignment left operand not a blackboard entry"
            raise ScriptError(msg)
        key, op, board = self.lhs.name, self.op, env.blackboard
        entry = board.get_entry(key)
        if entry is None:
            if op != ":=":
                msg = (
                    f"The blackboard entry [{key}] doesn't exist, yet. If you want to create a new one, "
                    f"use the operator [:=] instead of [=]"
                )
                raise ScriptError(msg)
            entry = board.create_entry(key, PortType.ANY)
        value = self.rhs.evaluate(env)
        if value is None:
            msg = f"The right operand of the operator [{op}] is not initialized"
            raise ScriptError(msg)
        board.note_write()
        current = entry.value
        try:
            if op in (":=", "="):
                if current is None and entry.info.kind == "any":
                    entry.value = value
                elif isinstance(value, str) and not isinstance(current, str):
                    if entry.info.has_converter:
                        entry.value = entry.info.parse(value, env.enums)
                    elif _is_num(current):
                        entry.value = _string_to_double(value, env)
                    else:
                        msg = f"entry [{key}] of type [{entry.info.name}]: cannot assign a string to it"
                        raise ScriptError(msg)
                else:
                    entry.value = copy_into(value, current)
            else:
                if current is None:
                    msg = f"The left operand of the operator [{op}] is not initialized"
                    raise ScriptError(msg)
                result: Any = current
                if _is_num(value):
                    if not _is_num(current):
                        msg = "This Assignment operator can't be used with a non-numeric type"
                        raise ScriptError(msg)
                    lhs, rhs = _to_double(current), _to_double(value)
                    if op == "+=":
                        result = lhs + rhs
                    elif op == "-=":
                        result = lhs - rhs
                    elif op == "*=":
                        result = lhs * rhs
                    else:
                        result = _divide(lhs, rhs)
                elif isinstance(value, str):
                    if op != "+=":
                        msg = "Operator not supported for strings"
                        raise ScriptError(msg)
                    result = value_to_string(current) + value
                entry.value = copy_into(result, current)
        except ConversionError as err:
            msg = f"Error assigning a value to entry [{key}]: {err}"
            raise ScriptError(msg) from None
        entry.seq += 1
        return entry.value


# -- parser ------------------------------------------------------------------------------------


def _fold_right(operands: list[_Expr], ops: list[str]) -> _Expr:
    """`a op1 b op2 c` as `a op1 (b op2 c)`."""
    result = operands[-1]
    for lhs, op in zip(reversed(operands[:-1]), reversed(ops), strict=True):
        result = _Binary(lhs, op, result)
    return result


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.index = 0
        # The operator group (math, bit or string) of each expression being parsed, innermost last:
        # BT.CPP's grammar lets one expression (a statement, a parenthesis or a conditional's middle)
        # use the operators of one group only, across its comparisons and logical operators too.
        self._groups: list[str | None] = []

    @property
    def tok(self) -> _Token:
        return self.tokens[self.index]

    def is_op(self, *ops: str) -> bool:
        tok = self.tokens[self.index]
        return tok.kind == _OP and tok.text in ops

    def advance(self) -> _Token:
        tok = self.tokens[self.index]
        self.index += 1
        return tok

    def fail(self, problem: str, tok: _Token | None = None) -> ScriptSyntaxError:
        where = tok if tok is not None else self.tok
        return ScriptSyntaxError(self.text, where.pos + 1, problem)

    def script(self) -> list[_Expr]:
        if self.tok.kind == _END:
            raise self.fail("empty script")
        exprs = [self.expression()]
        while self.is_op(";"):
            self.advance()
            if self.tok.kind == _END:
                raise self.fail("unexpected trailing ';'")
            exprs.append(self.expression())
        if self.tok.kind != _END:
            raise self.fail(f"unexpected {self.tok.text!r}")
        return exprs

    def expression(self) -> _Expr:
        self._groups.append(None)
        try:
            return self._expression()
        finally:
            self._groups.pop()

    def take_grouped(self) -> _Token:
        """Consume a math, bit or string operator; one of another group than the expression's is an error."""
        tok = self.tok
        group = _GROUP_OF[tok.text]
        seen = self._groups[-1]
        if seen is None:
            self._groups[-1] = group
        elif seen != group:
            raise self.fail(f"operator {tok.text!r} cannot be mixed with the previous operators; add parentheses")
        return self.advance()

    def _expression(self) -> _Expr:
        lhs = self.conditional()
        if self.tok.kind == _OP and self.tok.text in _ASSIGN_OPS:
            op = self.advance().text
            rhs = self.conditional()
            if self.tok.kind == _OP and self.tok.text in _ASSIGN_OPS:
                raise self.fail("assignments cannot be chained")
            return _Assign(lhs, op, rhs)
        return lhs

    def conditional(self) -> _Expr:
        condition = self.logical()
        if self.is_op("?"):
            self.advance()
            then = self.expression()
            if not self.is_op(":"):
                raise self.fail("expected ':' of the conditional operator")
            self.advance()
            else_ = self.logical()
            if self.is_op("?"):
                raise self.fail("conditional operators cannot be chained without parentheses")
            return _If(condition, then, else_)
        return condition

    def logical(self) -> _Expr:
        lhs = self.comparison()
        while self.is_op("||", "&&"):
            op = self.advance().text
            lhs = _Binary(lhs, op, self.comparison())
        return lhs

    def comparison(self) -> _Expr:
        first = self.group()
        if not (self.tok.kind == _OP and self.tok.text in _COMPARE_OPS):
            return first
        ops: list[str] = []
        operands = [first]
        while self.tok.kind == _OP and self.tok.text in _COMPARE_OPS:
            ops.append(self.advance().text)
            operands.append(self.group())
        return _Compare(ops, operands)

    def group(self) -> _Expr:
        """One comparison operand: a math, a bit or a concatenation chain; they do not mix."""
        if self.is_op("~", "!"):
            return self.bit_chain(None)
        if self.is_op("-"):
            return self.math_chain(None)
        first = self.atom()
        tok = self.tok
        if tok.kind == _OP:
            if tok.text in _BIT_OPS:
                return self.bit_chain(first)
            if tok.text in _ARITHMETIC_OPS:
                return self.math_chain(first)
            if tok.text == "..":
                return self.concat_chain(first)
        return first

    def no_mix(self, forbidden: frozenset[str]) -> None:
        tok = self.tok
        if tok.kind == _OP and tok.text in forbidden:
            raise self.fail(f"operator {tok.text!r} cannot be mixed with the previous operators; add parentheses")

    def math_chain(self, first: _Expr | None) -> _Expr:
        lhs = self.math_sum(first)
        self.no_mix(_BIT_OPS | {".."})
        return lhs

    # BT.CPP 4.8.2 groups `+ -` and `* /` from the right within their level: `10 - 4 - 3` is
    # 10 - (4 - 3), `100 / 10 / 2` is 100 / (10 / 2) (its issue #1029, fixed after 4.8.2).
    def math_sum(self, first: _Expr | None) -> _Expr:
        operands = [self.math_product(first)]
        ops: list[str] = []
        while self.is_op("+", "-"):
            ops.append(self.take_grouped().text)
            operands.append(self.math_product(None))
        return _fold_right(operands, ops)

    def math_product(self, first: _Expr | None) -> _Expr:
        operands = [first if first is not None else self.math_prefix()]
        ops: list[str] = []
        while self.is_op("*", "/"):
            ops.append(self.take_grouped().text)
            operands.append(self.math_prefix())
        return _fold_right(operands, ops)

    def math_prefix(self) -> _Expr:
        if self.is_op("-"):
            self.take_grouped()
            return _Unary("-", self.math_prefix())
        return self.atom()

    def concat_chain(self, first: _Expr) -> _Expr:
        lhs = first
        while self.is_op(".."):
            self.take_grouped()
            lhs = _Binary(lhs, "..", self.atom())
        self.no_mix(_BIT_OPS | _ARITHMETIC_OPS)
        return lhs

    def bit_chain(self, first: _Expr | None) -> _Expr:
        lhs = self.bit_and(first)
        while self.is_op("|", "^"):
            op = self.take_grouped().text
            lhs = _Binary(lhs, op, self.bit_and(None))
        self.no_mix(_ARITHMETIC_OPS | {".."})
        return lhs

    def bit_and(self, first: _Expr | None) -> _Expr:
        lhs = first if first is not None else self.bit_prefix()
        while self.is_op("&"):
            self.take_grouped()
            lhs = _Binary(lhs, "&", self.bit_prefix())
        return lhs

    def bit_prefix(self) -> _Expr:
        if self.is_op("~", "!"):
            op = self.take_grouped().text
            return _Unary(op, self.bit_prefix())
        return self.atom()

    def atom(self) -> _Expr:
        tok = self.tok
        if tok.kind == _OP and tok.text == "(":
            self.advance()
            inner = self.expression()
            if not self.is_op(")"):
                raise self.fail("expected ')'")
            self.advance()
            return inner
        if tok.kind in (_BOOL, _NUMBER, _STRING):
            self.advance()
            return _Literal(tok.value)
        if tok.kind == _NAME:
            self.advance()
            return _Name(tok.value)
        if tok.kind == _OP and tok.text == "+":
            after = self.tokens[self.index + 1]
            if after.kind == _NUMBER and after.pos == tok.pos + 1:
                self.index += 2
                return _Literal(after.value)
        raise self.fail("expected operand" if tok.kind == _END else f"expected operand, got {tok.text!r}")


class Script:
    """A parsed script; calling it runs it and returns the value of its last expression.

    Raises (when called):
        ScriptError: If the script fails while running.
    """

    __slots__ = ("_exprs", "source")

    def __init__(self, source: str, exprs: Sequence[_Expr]) -> None:
        self.source = source
        self._exprs = tuple(exprs)

    def __call__(self, env: Environment) -> Any:
        """Run the script and return the value of its last expression."""
        try:
            result: Any = None
            for expr in self._exprs:
                result = expr.evaluate(env)
            return result
        except TreeError as err:
            msg = f"error in script [{self.source}]: {err}"
            raise ScriptError(msg) from None
        except RecursionError:
            msg = f"error in script [{self.source}]: nested too deeply for twin to evaluate; split it up"
            raise ScriptError(msg) from None

    def __repr__(self) -> str:
        return f"Script({self.source!r})"


def parse_script(text: str) -> Script:
    """Parse a script.

    Raises:
        ScriptSyntaxError: With the column of the first problem.
    """
    try:
        return Script(text, _Parser(text).script())
    except RecursionError:
        raise ScriptSyntaxError(text, 1, "nested too deeply for twin to parse; split it up") from None


def script_truth(value: Any) -> bool:
    """A script result as a condition (`Any::cast<bool>`): 0/1 integers or any double.

    Raises:
        ScriptError: If the result is empty, a string, or an integer other than 0 and 1.
    """
    try:
        return bool(cast_value(value, PortType.BOOL))
    except ConversionError as err:
        msg = f"the script result {value!r} is not a boolean: {err}"
        raise ScriptError(msg) from None
