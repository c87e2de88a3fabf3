"""The request parser's scanning tools: phrase tables compiled to whole-word regexes (:func:`compile_table`) and
scanned leftmost-longest (:func:`scan`, a :class:`Hit` per phrase: character offsets into the text), a negation
before a word (:func:`negated`), sentences, and word runs and clause marks counted by binary search (:class:`Tokens`).
Pure; linear in the length of the text.
"""

from __future__ import annotations

import re
from bisect import bisect_left
from dataclasses import dataclass
from string import Template

from asset2sim.tasks.interpret import request_values as rv

_L = r"(?<![\w-])"

_R = r"(?![\w-])"


@dataclass(frozen=True)
class Hit:
    start: int
    end: int
    text: str
    value: object
    flag: str = ""


def compile_table(table: list[tuple[str, object, str]]) -> list[tuple[re.Pattern[str], object, str]]:
    return [(re.compile(_L + "(?:" + pat + ")" + _R), val, flag) for pat, val, flag in table]


def word_table(name: str) -> list[tuple[re.Pattern[str], object, str]]:
    """The phrase table ``name`` of ``words.yaml`` compiled (:func:`compile_table`): each ``${FRAGMENT}`` filled in,
    a list value as a tuple, the flag "" where none is given."""
    return compile_table([(Template(pat).substitute(rv.WORDS["fragments"]), tuple(val) if isinstance(val, list) else val, flag)
                          for pat, val, flag in (entry + [""] * (3 - len(entry)) for entry in rv.WORDS[name])])


def scan(text: str, table: list[tuple[re.Pattern[str], object, str]]) -> list[Hit]:
    """Non-overlapping matches of a pattern table: leftmost first, then longest."""
    return rv.leftmost_longest([Hit(m.start(), m.end(), m.group(0), val, flag) for pat, val, flag in table for m in pat.finditer(text)])


_NEG_BEFORE = re.compile(r"(?:\bnot|\bno|\bwithout|\bnever|n't|\bnon)(?:\s+\w+)?\s*[- ]?$")


def negated(text: str, start: int) -> bool:
    """A negation word within one word before ``start``."""
    return bool(_NEG_BEFORE.search(text[max(0, start - 24): start]))


def sentences(text: str) -> list[tuple[int, int]]:
    spans = []
    start = 0
    for m in re.finditer(r"(?<!\d)[.!?;](?!\d)|\n", text):
        if m.start() > start:
            spans.append((start, m.start()))
        start = m.end()
    if start < len(text):
        spans.append((start, len(text)))
    return spans


WORD_RUN = re.compile(r"[\w'-]+")

CLAUSE_MARK = re.compile(r"[,;:]")

TOKEN = re.compile(r"[\w'-]+|[,;:]")


class Tokens:
    """Word runs and clause marks of a text, found once, so a slice's tokens are counted by binary search."""

    def __init__(self, text: str):
        runs = list(WORD_RUN.finditer(text))
        self.starts = [m.start() for m in runs]
        self.ends = [m.end() for m in runs]
        self.marks = [m.start() for m in CLAUSE_MARK.finditer(text)]

    def count(self, a: int, b: int) -> int:
        """Number of tokens (``re.findall(r"[\\w'-]+|[,;:]", text[a:b])``)."""
        if b <= a:
            return 0
        i = bisect_left(self.starts, a)
        n = bisect_left(self.starts, b) - i
        if i > 0 and self.ends[i - 1] > a:
            n += 1
        return n + self.marks_between(a, b)

    def marks_between(self, a: int, b: int) -> int:
        """Number of ``[,;:]`` in text[a:b]."""
        return 0 if b <= a else bisect_left(self.marks, b) - bisect_left(self.marks, a)
