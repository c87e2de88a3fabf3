"""Decimal number lists of URDF attributes (``xyz="0 0 1"``): the strict reader's
:func:`parse_number_list` (finite decimal literals only) and the lenient one's
:func:`parse_number_list_lenient` (Python ``float`` of each token); both raise :class:`NumberError`.
"""

from __future__ import annotations

import math
import re

class NumberError(ValueError):
    """A numeric attribute is not acceptable; ``code`` is a ``NUMBER_*`` code."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_NAN = {"nan", "+nan", "-nan", "nan(ind)", "-nan(ind)", "qnan", "snan"}
_INF = {"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity", "1.#inf", "-1.#inf"}


def parse_number_list(text: str | None, count: int | tuple[int, ...]) -> tuple[float, ...]:
    """The finite floats of ``text``, a whitespace-separated list of decimal
    numbers, ``count`` of them (or one of a tuple of allowed counts).

    Raises:
        NumberError: with code NUMBER_EMPTY (empty or blank), NUMBER_NAN,
            NUMBER_INF, NUMBER_OVERFLOW (finite literal beyond float64),
            NUMBER_MALFORMED (anything but ``[+-]digits[.digits][e[+-]digits]``),
            NUMBER_COUNT (wrong number of values).
    """
    out = []
    for tok in _tokens(text):
        low = tok.lower()
        if low in _NAN:
            raise NumberError("NUMBER_NAN", f"{tok!r} is NaN")
        if low in _INF:
            raise NumberError("NUMBER_INF", f"{tok!r} is infinite")
        if not _DECIMAL.match(tok):
            raise NumberError("NUMBER_MALFORMED", f"{tok!r} is not a decimal number")
        v = float(tok)
        if not math.isfinite(v):
            raise NumberError("NUMBER_OVERFLOW", f"{tok!r} overflows a 64-bit float")
        out.append(v)
    _check_count(out, text, count)
    return tuple(out)


def _tokens(text: str | None) -> list[str]:
    """The whitespace-separated tokens of ``text`` (NumberError NUMBER_EMPTY: none)."""
    if text is None or not text.strip():
        raise NumberError("NUMBER_EMPTY", "empty value where a number is required")
    return text.split()


def _check_count(values: list[float], text: str, count: int | tuple[int, ...]) -> None:
    allowed = (count,) if isinstance(count, int) else count
    if len(values) not in allowed:
        want = " or ".join(str(c) for c in allowed)
        raise NumberError("NUMBER_COUNT", f"{len(values)} value(s) in {text!r}, expected {want}")


def parse_number_list_lenient(text: str | None, count: int | tuple[int, ...]) -> tuple[float, ...]:
    """``float`` of every token (NaN and infinities accepted), right count."""
    tokens = _tokens(text)
    try:
        out = [float(tok) for tok in tokens]
    except ValueError as exc:
        raise NumberError("NUMBER_MALFORMED", str(exc)) from None
    _check_count(out, text, count)
    return tuple(out)

