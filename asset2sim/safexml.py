"""Hardened XML parsing for untrusted assets.

:func:`parse_xml_bytes` parses with expat and refuses any ``<!DOCTYPE`` (so no
entity is declared or expanded and nothing external is fetched), and anything
beyond the :class:`XMLLimits` (size, token length, depth, element count).
Refusals are :class:`SafeXMLError` with a stable ``code``, ``source`` and line.
Elements carry ``sourceline``; comments and processing instructions are
dropped; namespaces are not processed.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
import xml.parsers.expat as expat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic

__all__ = [
    "XMLLimits", "SourceElement", "SafeXMLError", "XMLTooLarge", "XMLTokenTooLarge", "XMLTooDeep", "XMLTooManyElements",
    "XMLDTDForbidden", "XMLEntityForbidden", "XMLExternalReferenceForbidden", "XMLMalformed", "XMLNotAFile",
    "parse_xml_bytes", "read_xml_file", "parse_xml_file"
]


@dataclass(frozen=True)
class XMLLimits:
    """Caps applied while parsing (bytes or elements); defaults far above any
    real URDF and far below what hurts."""

    max_bytes: int = 16 * 1024 * 1024
    """Whole document, bytes."""
    max_token_bytes: int = 1024 * 1024
    """Longest run of bytes without ``<`` or ``>`` and longest attribute value
    or text node, bytes (UTF-8)."""
    max_depth: int = 64
    """Deepest element nesting (the root is depth 1)."""
    max_elements: int = 100_000
    """Elements in the document."""


DEFAULT_LIMITS = XMLLimits()


class SourceElement(ET.Element):
    """An ElementTree element that remembers the line of its start tag."""

    sourceline: int | None = None


class SafeXMLError(ValueError):
    """The XML was refused. ``code`` is stable (``XML_...``), ``source`` names
    the file (or what the bytes came from), ``line`` is 1-based or None."""

    code = "XML_REFUSED"

    def __init__(self, message: str, *, source: str = "<bytes>", line: int | None = None):
        self.source = source
        self.line = line
        self.detail = message
        where = f"{source}:{line}" if line else source
        super().__init__(f"{where}: {self.code}: {message}")


class XMLTooLarge(SafeXMLError):
    code = "XML_TOO_LARGE"


class XMLTokenTooLarge(SafeXMLError):
    code = "XML_TOKEN_TOO_LARGE"


class XMLTooDeep(SafeXMLError):
    code = "XML_TOO_DEEP"


class XMLTooManyElements(SafeXMLError):
    code = "XML_TOO_MANY_ELEMENTS"


class XMLDTDForbidden(SafeXMLError):
    code = "XML_DTD_FORBIDDEN"


class XMLEntityForbidden(SafeXMLError):
    code = "XML_ENTITY_FORBIDDEN"


class XMLExternalReferenceForbidden(SafeXMLError):
    code = "XML_EXTERNAL_REFERENCE_FORBIDDEN"


class XMLMalformed(SafeXMLError):
    code = "XML_MALFORMED"


class XMLNotAFile(SafeXMLError):
    code = "XML_NOT_A_FILE"


_LT, _GT = 0x3C, 0x3E
_SCAN_CHUNK = 1 << 22  # 4 MiB: bounds the scan's temporary memory


def _longest_run_without_markup(data: bytes) -> tuple[int, int]:
    """(length, start offset) of the longest run of bytes without ``<`` or ``>``."""
    arr = np.frombuffer(data, dtype=np.uint8)
    n = arr.size
    best, best_at = 0, 0
    last = -1  # offset of the previous delimiter
    for lo in range(0, n, _SCAN_CHUNK):
        chunk = arr[lo : lo + _SCAN_CHUNK]
        pos = np.flatnonzero((chunk == _LT) | (chunk == _GT))
        if pos.size == 0:
            continue
        pos = pos + lo
        gaps = np.diff(pos, prepend=last) - 1
        i = int(np.argmax(gaps))
        if gaps[i] > best:
            best, best_at = int(gaps[i]), int(pos[i] - gaps[i])
        last = int(pos[-1])
    tail = n - last - 1
    if tail > best:
        best, best_at = tail, last + 1
    return best, best_at


def parse_xml_bytes(data: bytes, source: str = "<bytes>", limits: XMLLimits | None = None) -> SourceElement:
    """The root :class:`SourceElement` of untrusted XML ``data`` (any encoding
    expat supports), ``source`` naming it in messages.

    Raises:
        XMLTooLarge, XMLTokenTooLarge, XMLTooDeep, XMLTooManyElements: beyond ``limits``.
        XMLDTDForbidden, XMLEntityForbidden, XMLExternalReferenceForbidden: a
            ``<!DOCTYPE``, an entity declaration, an external DTD or entity.
        XMLMalformed: not well-formed, or not bytes.
    """
    lim = limits or DEFAULT_LIMITS
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise XMLMalformed(f"expected bytes, got {type(data).__name__}", source=source)
    data = bytes(data)
    if len(data) > lim.max_bytes:
        raise XMLTooLarge(f"{len(data)} bytes > limit {lim.max_bytes}", source=source)
    run, at = _longest_run_without_markup(data)
    if run > lim.max_token_bytes:
        raise XMLTokenTooLarge(f"a token of {run} bytes (starting at byte {at}) > limit {lim.max_token_bytes}",
                               source=source, line=data.count(b"\n", 0, at) + 1)
    parser = expat.ParserCreate()
    # Never read external DTD subsets or parameter entities.
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    builder = ET.TreeBuilder(element_factory=SourceElement)
    _install_guards(parser, builder, lim, source)
    try:
        parser.Parse(data, True)
    except SafeXMLError:
        # a guard's refusal, raised in a handler (expat passes it on as it is)
        raise
    except expat.ExpatError as exc:
        raise XMLMalformed(f"{expat.errors.messages[exc.code] if exc.code else exc} (line {exc.lineno}, column {exc.offset})",
                           source=source, line=exc.lineno) from None
    except (UnicodeError, ValueError) as exc:  # e.g. an unknown declared encoding
        raise XMLMalformed(str(exc), source=source) from None
    return builder.close()  # type: ignore[return-value]


def _install_guards(parser, builder: ET.TreeBuilder, lim: XMLLimits, source: str) -> None:
    """Expat handlers that build the tree into ``builder`` and raise the :class:`SafeXMLError` of the first DTD,
    entity, external reference or exceeded limit."""
    state = {"depth": 0, "elements": 0, "text": 0}

    def fail(cls: type[SafeXMLError], message: str) -> None:
        raise cls(message, source=source, line=parser.CurrentLineNumber)

    def start_doctype(name, sysid, pubid, has_internal_subset):
        if sysid or pubid:
            fail(XMLExternalReferenceForbidden, f"external DTD {sysid or pubid!r} in <!DOCTYPE {name}>")
        state["doctype"] = name

    def end_doctype():
        fail(XMLDTDForbidden, f"document type declaration <!DOCTYPE {state.get('doctype')}> is not allowed")

    def entity_decl(name, is_param, value, base, sysid, pubid, notation):
        kind = "parameter entity" if is_param else "entity"
        if sysid or pubid or notation:
            fail(XMLExternalReferenceForbidden, f"external {kind} {name!r} -> {sysid or pubid or notation!r}")
        fail(XMLEntityForbidden, f"{kind} declaration {name!r} (entity expansion is not allowed)")

    def unparsed_entity(name, base, sysid, pubid, notation):
        fail(XMLExternalReferenceForbidden, f"unparsed entity {name!r} -> {sysid!r}")

    def external_ref(context, base, sysid, pubid):
        fail(XMLExternalReferenceForbidden, f"external entity reference -> {sysid or pubid!r}")

    def start(tag, attrs):
        state["depth"] += 1
        state["elements"] += 1
        if state["depth"] > lim.max_depth:
            fail(XMLTooDeep, f"nesting deeper than {lim.max_depth} elements")
        if state["elements"] > lim.max_elements:
            fail(XMLTooManyElements, f"more than {lim.max_elements} elements")
        for k, v in attrs.items():
            if len(v) > lim.max_token_bytes:
                fail(XMLTokenTooLarge, f"attribute {k!r} of <{tag}> has {len(v)} characters > limit {lim.max_token_bytes}")
        state["text"] = 0
        builder.start(tag, attrs).sourceline = parser.CurrentLineNumber

    def end(tag):
        state["depth"] -= 1
        state["text"] = 0
        builder.end(tag)

    def chars(text):
        state["text"] += len(text)
        if state["text"] > lim.max_token_bytes:
            fail(XMLTokenTooLarge, f"a text node longer than {lim.max_token_bytes} characters")
        builder.data(text)

    parser.StartDoctypeDeclHandler = start_doctype
    parser.EndDoctypeDeclHandler = end_doctype
    parser.EntityDeclHandler = entity_decl
    parser.UnparsedEntityDeclHandler = unparsed_entity
    parser.ExternalEntityRefHandler = external_ref
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    parser.buffer_text = True


def read_xml_file(path: Path | str, limits: XMLLimits | None = None) -> bytes:
    """Read a regular file for :func:`parse_xml_bytes` without blocking on a
    FIFO or reading more than ``max_bytes + 1`` bytes.

    Raises:
        XMLNotAFile: missing, unreadable, or not a regular file.
        XMLTooLarge: larger than ``limits.max_bytes``.
    """
    lim = limits or DEFAULT_LIMITS
    src = str(path)
    try:
        fh = atomic.open_regular(src)
    except atomic.NotRegularFileError:
        raise XMLNotAFile("not a regular file", source=src) from None
    except OSError as exc:
        raise XMLNotAFile(f"cannot open: {exc.strerror or exc}", source=src) from None
    with fh:
        try:
            size = os.fstat(fh.fileno()).st_size
            if size > lim.max_bytes:
                raise XMLTooLarge(f"{size} bytes > limit {lim.max_bytes}", source=src)
            data = fh.read(lim.max_bytes + 1)
        except OSError as exc:
            raise XMLNotAFile(f"cannot read: {exc.strerror or exc}", source=src) from None
    if len(data) > lim.max_bytes:
        raise XMLTooLarge(f"more than {lim.max_bytes} bytes", source=src)
    return data


def parse_xml_file(path: Path | str) -> SourceElement:
    """:func:`read_xml_file` then :func:`parse_xml_bytes` under the default limits (same errors)."""
    return parse_xml_bytes(read_xml_file(path), source=str(path))
