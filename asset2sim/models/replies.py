"""Strict parsing of model replies (:class:`ReplyInvalid`, one line per problem), and the message
that asks again."""

from __future__ import annotations

import json
import math
import re
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from asset2sim.models.errors import ReplyInvalid

M = TypeVar("M", bound=BaseModel)

#: Deepest nesting of arrays and objects a reply may have (the reply schemas need fewer than 10).
MAX_JSON_DEPTH = 64

_NESTING = re.compile(r'[\[\]{}"\\]')


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"duplicate key {k!r}")
        out[k] = v
    return out


def _no_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed")


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"number {text} overflows to a non-finite value")
    return x


def _strip_fence(text: str) -> str:
    """Remove one Markdown code fence (```json ... ```) around the whole text."""
    t = text.strip()
    if t.startswith("```") and t.endswith("```") and len(t) >= 6:
        first_nl = t.find("\n")
        if first_nl > 0 and t[3:first_nl].strip().lower() in ("", "json"):
            return t[first_nl + 1 : -3].strip()
    return t


def json_depth_exceeds(text: str) -> bool:
    """Whether ``text`` opens more than :data:`MAX_JSON_DEPTH` arrays / objects inside each other (outside
    strings): one linear pass, no recursion, so a reply nested 100,000 deep is refused before a
    decoder recurses into it."""
    depth = 0
    in_string = False
    skip = -1  # the position of a character a backslash escapes
    for m in _NESTING.finditer(text):
        i, c = m.start(), m.group()
        if i == skip:
            continue
        if in_string:
            if c == "\\":
                skip = i + 1
            elif c == '"':
                in_string = False
            continue
        if c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            if depth > MAX_JSON_DEPTH:
                return True
        elif c in "]}":
            depth -= 1
    return False


def parse_json_strict(text: str) -> dict[str, Any]:
    """Parse exactly one JSON object (one Markdown fence around it tolerated).

    Raises:
        ReplyInvalid: prose, several values, truncation, duplicate keys, NaN / Infinity /
            overflowing numbers, nesting deeper than :data:`MAX_JSON_DEPTH`.
    """
    t = _strip_fence(text)
    too_deep = f"invalid JSON: nested deeper than {MAX_JSON_DEPTH} arrays or objects"
    if json_depth_exceeds(t):
        raise ReplyInvalid([too_deep])
    dec = json.JSONDecoder(object_pairs_hook=_no_duplicates, parse_constant=_no_constant,
                           parse_float=_finite_float)
    try:
        obj, end = dec.raw_decode(t)
    except RecursionError:
        raise ReplyInvalid([too_deep]) from None
    except json.JSONDecodeError as exc:
        what = "the reply is not JSON" if exc.pos == 0 else "invalid or truncated JSON"
        raise ReplyInvalid([f"{what}: {exc.msg} at line {exc.lineno} column {exc.colno} "
                            f"(character {exc.pos} of {len(t)})"]) from None
    except ValueError as exc:  # a duplicate key, a non-finite number (the hooks above), an integer with too many digits
        raise ReplyInvalid([f"invalid JSON: {exc}"]) from None
    if t[end:].strip():
        raise ReplyInvalid([f"extra text after the JSON object at character {end} of {len(t)}"])
    if not isinstance(obj, dict):
        raise ReplyInvalid([f"the reply must be one JSON object, got {type(obj).__name__}"])
    return obj


def _shown(got: Any) -> str:
    """A rejected scalar value as the error line shows it (JSON where it is JSON), 60 characters."""
    try:
        return json.dumps(got)[:60]
    except (TypeError, ValueError):
        return repr(got)[:60]


def pydantic_errors(exc: ValidationError, limit: int = 30) -> list[str]:
    """One line per error: ``path.to.field: message (got value)``."""
    out = []
    for e in exc.errors()[:limit]:
        loc = ".".join(str(p) for p in e.get("loc", ())) or "(top level)"
        got = e.get("input")
        got_s = "" if isinstance(got, (dict, list)) else f" (got {_shown(got)})"
        out.append(f"{loc}: {e.get('msg', 'invalid')}{got_s}")
    if len(exc.errors()) > limit:
        out.append(f"... and {len(exc.errors()) - limit} more errors")
    return out


def parse_reply(text: str, model_cls: type[M]) -> M:
    """Strict JSON, then ``model_cls`` in pydantic strict mode; ReplyInvalid lists every problem."""
    obj = parse_json_strict(text)
    try:
        return model_cls.model_validate(obj, strict=True)
    except ValidationError as exc:
        raise ReplyInvalid(pydantic_errors(exc)) from None


def reask_text(errors: list[str]) -> str:
    """The follow-up message listing a reply's problems."""
    lines = "\n".join(f"- {e}" for e in errors[:30])
    return (
        "Your previous reply could not be used:\n"
        f"{lines}\n"
        "Answer again with exactly one JSON object that follows the schema: every field present, "
        "no other fields, finite numbers within the stated ranges, names exactly as in the "
        "description. No prose, no Markdown."
    )


def excerpt(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters, saying how many were left out."""
    return text if len(text) <= limit else text[:limit] + f"... [{len(text) - limit} more characters omitted]"
