"""Text that came from a user or an input, made inert for the medium it is shown in.

Names (links, joints, bodies, prims, manifest ids, methods), request and task text, file paths and the
messages that quote them are data. Wherever they are shown they pass through the one helper of that medium:

- :func:`terminal`: a terminal line. C0 control characters but the newline and the tab (ESC, BEL, backspace,
  carriage return ...), DEL, C1 control characters (CSI ``\\x9b``, OSC ``\\x9d`` ...) and the Unicode
  bidirectional overrides and isolates are shown as their escapes (``\\x1b``, ``\\u202e``), so no control sequence
  from a name reaches the terminal (colours, the window title, a cursor moved back over what was printed);
- :func:`markup`: a string handed to ``rich`` as console markup: :func:`terminal`, then ``rich.markup.escape``
  (a name ``[/bold]`` is printed, not parsed);
- :func:`html_text`: HTML text or an attribute value (``html.escape`` with quotes; control characters as in
  :func:`terminal`);
- :func:`markdown_text`: Markdown text (``audit.md``): HTML escaped (Markdown viewers render raw HTML) and the
  characters of Markdown's syntax (``\ ` * _ [ ] |``) backslash-escaped, so a name stays one table cell of text;
- :func:`plot_text`: a matplotlib label: ``$`` escaped, so a name is never read as mathtext (the figures also
  draw with ``text.parse_math`` off, :data:`asset2sim.tasks.evaluation.plots.STYLE`);
- :func:`one_line`: a message stored or shown in one sentence (a note, ``report.json``, an error line): its first
  line, no traceback, at most :data:`MAX_LINE` characters;
- :func:`field_errors`: pydantic's validation errors as one sentence, ``field: message; ...`` (no library text
  or URL);
- :func:`csv_cell`: a CSV cell a spreadsheet reads as text, never as a formula;
- :data:`CSP_META`: the Content-Security-Policy every HTML page asset2sim writes or serves carries, so that even a
  name that escaped :func:`html_text` could run no script.

Every function takes any object (``str()`` of it) and returns ``str``; none raises.
"""

from __future__ import annotations

import difflib
import html
import re

__all__ = ["CONTENT_SECURITY_POLICY", "CSP_META", "MAX_LINE", "MAX_NAME", "csv_cell", "csv_text", "field_errors", "html_text", "markdown_text", "markup", "one_line",
           "plot_text", "shorten", "terminal"]

#: Characters of a one-line message (:func:`one_line`).
MAX_LINE = 300
#: Characters of a name shown on a terminal line or in a label (:func:`shorten`); the rest is elided.
MAX_NAME = 200

#: C0 controls but tab and newline, DEL, C1 controls, the bidirectional marks, embeddings, overrides and isolates.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
_CONTROL_LINE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]")
_TRACEBACK = re.compile(r"\s*Traceback \(most recent call last\)")


def _escape(match: re.Match) -> str:
    c = ord(match.group())
    return f"\\x{c:02x}" if c < 0x100 else f"\\u{c:04x}"


def shorten(text: object, limit: int = MAX_NAME) -> str:
    """``str(text)`` cut to ``limit`` characters (the middle elided with ``...``, both ends kept)."""
    s = str(text)
    if len(s) <= limit:
        return s
    keep = max(1, (limit - 3) // 2)
    return f"{s[:keep]}...{s[-keep:]}"


def terminal(text: object, *, newlines: bool = True) -> str:
    """``str(text)`` with every control character shown as its escape (module docstring); ``newlines`` False
    escapes newlines and tabs too (a name on one line)."""
    return (_CONTROL if newlines else _CONTROL_LINE).sub(_escape, str(text))


def markup(text: object) -> str:
    """``text`` for ``rich`` console markup: :func:`terminal`, then ``rich.markup.escape``."""
    from rich.markup import escape

    return escape(terminal(text))


def html_text(text: object) -> str:
    """``text`` as HTML text or a quoted attribute value: control characters escaped as on a terminal, then
    ``&``, ``<``, ``>``, ``"`` and ``'`` as character references."""
    return html.escape(terminal(text), quote=True)


_MARKDOWN = re.compile(r"([\\`*_\[\]|])")


def markdown_text(text: object) -> str:
    """``text`` as Markdown text: control characters and newlines escaped as on a terminal, ``&``, ``<`` and ``>`` as
    character references, and ``\ ` * _ [ ] |`` backslash-escaped."""
    return _MARKDOWN.sub(r"\\\1", html.escape(terminal(text, newlines=False), quote=False))


def plot_text(text: object) -> str:
    """``text`` for a matplotlib label: control characters escaped, ``$`` as ``\\$`` (never mathtext)."""
    return terminal(text).replace("$", r"\$")


def one_line(text: object, limit: int = MAX_LINE) -> str:
    """The first line of ``text`` (a Python traceback and what follows it cut off), control characters escaped,
    at most ``limit`` characters (``...`` marking a cut): one sentence for a note, an error line or
    ``report.json``."""
    lines = [ln.strip() for ln in _TRACEBACK.split(str(text), 1)[0].splitlines() if ln.strip()]
    s = terminal(lines[0] if lines else "", newlines=False)
    return s if len(s) <= limit else s[: max(0, limit - 3)].rstrip() + "..."


def field_errors(exc: object) -> str:
    """A pydantic ``ValidationError`` as one sentence, ``field.sub: message; ...`` (a message naming its field says it
    once; ``Value error, `` dropped): the field and what is wrong, without pydantic's type tags, input echo or URL."""
    out = []
    for e in exc.errors():  # type: ignore[attr-defined]
        field, msg = ".".join(str(x) for x in e["loc"]) or "value", str(e["msg"]).removeprefix("Value error, ")
        out.append(msg if msg.startswith(f"{field}: ") else f"{field}: {msg}")
    return one_line("; ".join(out), 4 * MAX_LINE)


#: What a spreadsheet reads as the start of a formula (OWASP, "CSV Injection"): ``= + - @``, a tab, a carriage return.
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: object) -> object:
    """``value`` as a CSV cell a spreadsheet shows as text: a string that starts like a formula (:data:`FORMULA_START`)
    gets a leading ``'``; numbers and every other value unchanged (a negative number stays a number)."""
    return "'" + value if isinstance(value, str) and value.startswith(FORMULA_START) else value


def csv_text(frame) -> str:
    """The CSV text (no index) of a pandas DataFrame with every cell through :func:`csv_cell`, the header too."""
    safe = frame.map(csv_cell)
    safe.columns = [csv_cell(c) for c in safe.columns]
    return safe.to_csv(index=False)


#: The Content-Security-Policy of every HTML page asset2sim writes (``report.html``, the benchmark pages) or serves (the
#: rating app): no script, plugin, frame or form to another site, no ``<base>``; styles inline; images and videos from
#: the page's own folder (``'self'``, ``file:`` for a page opened from disk) or inline ``data:``.
CONTENT_SECURITY_POLICY = ("default-src 'none'; style-src 'unsafe-inline'; img-src 'self' file: data:; media-src 'self' file:; "
                           "form-action 'self'; base-uri 'none'")
#: :data:`CONTENT_SECURITY_POLICY` as the ``<meta>`` element of a page's ``<head>``.
CSP_META = f'<meta http-equiv="Content-Security-Policy" content="{CONTENT_SECURITY_POLICY}">'


def did_you_mean(word: str, choices, most: int = 1) -> str:
    """``"; did you mean X, Y?"``: up to ``most`` of ``choices`` closest to a mistyped ``word``
    (:func:`difflib.get_close_matches`, ratio >= 0.6), else ``""``."""
    close = difflib.get_close_matches(word, sorted(set(choices)), n=most, cutoff=0.6)
    return f"; did you mean {', '.join(close)}?" if close else ""
