"""What the commands write to the terminal, made inert (:mod:`asset2sim.inert`).

:func:`inert_streams` wraps ``sys.stdout`` and ``sys.stderr`` while a command runs (:func:`asset2sim.cli.main`): every
``print`` and log line is written with its control characters shown as escapes (a request holding ESC, an OSC
window title, BEL or backspaces reaches the terminal as ``\\x1b``, ``\\x07``, ``\\x08``). ``rich`` writes its own
styles as escape sequences, so its consoles (:func:`console`) write to the streams beneath, and the commands hand it
user-derived text through :func:`asset2sim.inert.markup` (markup escaped, control characters shown as escapes).
"""

from __future__ import annotations

import contextlib
import sys
from typing import Any, Iterator, TextIO

from asset2sim import inert


class InertStream:
    """A text stream whose :meth:`write` shows control characters (but newline and tab) as escapes; every other
    attribute is the wrapped stream's (``raw``) but :meth:`isatty`, False: a library that captures the stream (a
    logging handler drawing with rich) writes no escape sequences of its own, which would be shown as text. The
    commands' own consoles see the terminal beneath (:func:`raw`, :func:`console`)."""

    def __init__(self, raw: TextIO):
        self.raw = raw

    def isatty(self) -> bool:
        return False

    def write(self, text: str) -> int:
        self.raw.write(inert.terminal(text))
        return len(text)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)


def raw(stream: Any) -> Any:
    """The stream beneath an :class:`InertStream` (``stream`` itself otherwise)."""
    while isinstance(stream, InertStream):
        stream = stream.raw
    return stream


@contextlib.contextmanager
def inert_streams() -> Iterator[None]:
    """``sys.stdout`` and ``sys.stderr`` wrapped in :class:`InertStream` while the block runs."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = InertStream(raw(out)), InertStream(raw(err))
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err


def console(*, width: int | None = None):
    """A ``rich`` console on the stream beneath standard output: a terminal's width (at least ``width``
    when given); for a pipe or a file, 200 columns with lines kept whole (for grep). Text handed to it must pass
    through :func:`asset2sim.inert.markup`."""
    from rich.console import Console

    stream = raw(sys.stdout)
    if stream.isatty():
        probe = Console(file=stream)
        return Console(file=stream, width=max(probe.width, width) if width else None)
    return Console(file=stream, width=max(200, width or 0), soft_wrap=True)
