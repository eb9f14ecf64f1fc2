"""A small VRML97 reader: the subset of ``#VRML V2.0 utf8`` that model files use, as meshes.

The text is parsed into a tree of :class:`_Node` (PROTO instances already expanded, USE sharing
the DEF'd node), then walked with the current transform to make one :class:`MeshPart` per
Shape. Numeric lists (``point [...]``, ``coordIndex [...]``) are converted in bulk with numpy.
"""

from __future__ import annotations

import gzip
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SonarRasterError
from .scene import MeshPart

log = logging.getLogger(__name__)

#: Segments around the axis of Cylinder, Cone and Sphere (the sphere has half as many rings).
SEGMENTS = 32

_HEADER = "#VRML V2.0 utf8"
_SKIP = re.compile(r"(?:[\s,]+|#[^\n]*)*")
_TOKEN = re.compile(
    r"""(?P<num>[+-]?(?:0[xX][0-9a-fA-F]+|(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?))
      | (?P<str>"(?:[^"\\]|\\.)*")
      | (?P<punct>[{}\[\]])
      | (?P<id>[^\x00-\x20"#'+,\-.\[\\\]{}0-9\x7f][^\x00-\x20"#',\[\\\]{}\x7f]*)""",
    re.VERBOSE | re.DOTALL,
)
_LIST_STOP = re.compile(r'[#\]{}"]')
_GROUPS = {"Group", "Transform", "Collision", "Anchor", "Billboard"}
_IN_OUT = {"eventIn", "eventOut", "inputOnly", "outputOnly"}
_FIELD_DECL = {"field", "exposedField", "initializeOnly", "inputOutput"}
_MISSING = object()


@dataclass
class _Source:
    """A parsed text: its name for messages and the offsets of its line breaks."""

    name: str
    text: str
    _breaks: np.ndarray | None = None

    def line(self, pos: int) -> int:
        """1-based line number of character offset ``pos``."""
        if self._breaks is None:
            self._breaks = np.array([m.start() for m in re.finditer("\n", self.text)], dtype=int)
        return int(np.searchsorted(self._breaks, pos)) + 1

    def error(self, pos: int, message: str) -> SonarRasterError:
        """A one-line error ``name:line: message`` located at ``pos``."""
        return SonarRasterError(f"{self.name}:{self.line(pos)}: {message}")


@dataclass
class _Node:
    """One parsed node: its type, its fields and where it came from."""

    type: str
    fields: dict[str, Any]
    src: _Source
    pos: int
    base_dir: Path | None
    def_name: str | None = None


@dataclass(frozen=True)
class _IsRef:
    """``field IS name`` inside a PROTO body, replaced when the PROTO is instantiated."""

    name: str


@dataclass
class _Proto:
    """A PROTO (body parsed, IS references unresolved) or an unresolved EXTERNPROTO."""

    name: str
    defaults: dict[str, Any]
    body: list[_Node] = field(default_factory=list)
    urls: list[str] | None = None


@dataclass(frozen=True)
class _Tok:
    kind: str  # "num", "str", "id", "{", "}", "[", "]" or "eof"
    text: str
    pos: int


class _Lexer:
    """Tokens of a VRML text, with numeric lists read in one numpy call."""

    def __init__(self, src: _Source, start: int = 0) -> None:
        self.src, self.text, self.pos = src, src.text, start
        self._peeked: _Tok | None = None

    def peek(self) -> _Tok:
        """The next token, not consumed."""
        if self._peeked is None:
            pos = _SKIP.match(self.text, self.pos).end()  # type: ignore[union-attr]
            if pos >= len(self.text):
                self._peeked = _Tok("eof", "end of file", pos)
            else:
                m = _TOKEN.match(self.text, pos)
                if m is None:
                    raise self.src.error(pos, f"unexpected character {self.text[pos]!r}; "
                                              "fix the VRML syntax")
                kind = m.lastgroup if m.lastgroup != "punct" else m.group()
                self._peeked = _Tok(kind or "", m.group(), pos)
                pos = m.end()
            self.pos = pos
        return self._peeked

    def next(self) -> _Tok:
        """Consume and return the next token."""
        tok = self.peek()
        self._peeked = None
        return tok

    def expect(self, kind: str, what: str) -> _Tok:
        """Consume a token of ``kind`` or raise naming ``what`` was expected."""
        tok = self.next()
        if tok.kind != kind:
            raise self.src.error(tok.pos, f"expected {what}, found {tok.text!r}; "
                                          "fix the VRML syntax")
        return tok

    def number_list(self, open_pos: int) -> np.ndarray:
        """Read numbers up to the ``]`` that closes the list opened at ``open_pos``."""
        start = self.peek().pos
        self._peeked = None
        pieces, i = [], start
        while True:
            m = _LIST_STOP.search(self.text, i)
            if m is None:
                raise self.src.error(open_pos, "'[' is never closed; add the missing ']'")
            pieces.append(self.text[i : m.start()])
            if m.group() == "#":
                eol = self.text.find("\n", m.start())
                i = len(self.text) if eol < 0 else eol
            elif m.group() == "]":
                self.pos = m.end()
                break
            else:
                raise self.src.error(m.start(), f"expected a number or ']', found "
                                                f"{m.group()!r}; close the list opened on "
                                                f"line {self.src.line(open_pos)}")
        words = "".join(pieces).replace(",", " ").split()
        try:
            return np.array(words, dtype=np.float64)
        except ValueError:
            return self._slow_numbers(words, start)

    def _slow_numbers(self, words: list[str], start: int) -> np.ndarray:
        """Convert hexadecimal integers, or raise at the first word that is not a number."""
        out = np.empty(len(words))
        for k, word in enumerate(words):
            m = _TOKEN.fullmatch(word)
            if m is None or m.lastgroup != "num":
                raise self.src.error(self.text.find(word, start), f"expected a number, found "
                                                                  f"{word!r}; fix the VRML syntax")
            out[k] = _number(word)
        return out


def _number(text: str) -> float:
    return float(int(text, 16)) if text.lstrip("+-")[:2] in ("0x", "0X") else float(text)


class _Parser:
    """Recursive-descent parser from a VRML97 text to a list of root nodes."""

    def __init__(self, src: _Source, base_dir: Path | None, stack: tuple[Path, ...]) -> None:
        self.src, self.base_dir, self.stack = src, base_dir, stack
        self.lex = _Lexer(src)
        self.defs: dict[str, _Node | None] = {}
        self.protos: dict[str, _Proto] = {}

    def parse(self) -> list[_Node]:
        """Check the header and parse every statement of the file."""
        text = self.src.text.lstrip("\ufeff")
        if not text.startswith(_HEADER):
            hint = ("VRML 1.0 is not supported; convert the file to VRML97"
                    if text.startswith("#VRML V1.0") else
                    f"not a VRML97 file; the first line must be '{_HEADER}'")
            raise self.src.error(0, hint)
        return self.statements("eof")  # the header line is a comment

    def statements(self, end: str) -> list[_Node]:
        """Nodes up to (and consuming) a token of kind ``end``; PROTO and ROUTE are absorbed."""
        nodes = []
        while self.lex.peek().kind != end:
            tok = self.lex.next()
            if tok.kind != "id":
                closing = {"eof": "end of file", "]": "']'", "}": "'}'"}[end]
                raise self.src.error(tok.pos, f"expected a node or {closing}, found "
                                              f"{tok.text!r}; fix the VRML syntax")
            node = self.statement(tok)
            if node is not None:
                nodes.append(node)
        self.lex.next()
        return nodes

    def statement(self, tok: _Tok) -> _Node | None:
        """One statement starting with identifier ``tok``."""
        if tok.text == "PROTO":
            self.proto()
            return None
        if tok.text == "EXTERNPROTO":
            self.externproto()
            return None
        if tok.text == "ROUTE":
            for _ in range(3):
                self.lex.expect("id", "a ROUTE 'node.field TO node.field'")
            return None
        return self.node_statement(tok)

    def node_statement(self, tok: _Tok) -> _Node | None:
        """``DEF name Node {...}``, ``USE name`` or ``Node {...}``."""
        if tok.text == "USE":
            name = self.lex.expect("id", "a DEF name after USE")
            if name.text not in self.defs:
                raise self.src.error(name.pos, f"USE {name.text} before any DEF {name.text}; "
                                               "define the node first")
            return self.defs[name.text]
        def_name = None
        if tok.text == "DEF":
            def_name = self.lex.expect("id", "a name after DEF").text
            tok = self.lex.expect("id", f"a node type after DEF {def_name}")
        node = self.node(tok, def_name)
        if def_name is not None:
            self.defs[def_name] = node
        return node

    def node(self, tok: _Tok, def_name: str | None) -> _Node | None:
        """The node whose type name is ``tok``; a PROTO instance expands to its body."""
        self.lex.expect("{", f"'{{' after {tok.text}")
        fields = self.fields(tok)
        proto = self.protos.get(tok.text)
        if proto is None:
            return _Node(tok.text, fields, self.src, tok.pos, self.base_dir, def_name)
        if proto.urls is not None:
            raise self.src.error(tok.pos, f"EXTERNPROTO {tok.text} has no local file among "
                                          f"{proto.urls}; put that file next to this one")
        if not proto.body:
            return None
        node = _substitute(proto.body[0], {**proto.defaults, **fields}, {})
        if def_name is not None:
            node.def_name = def_name
        return node

    def fields(self, owner: _Tok) -> dict[str, Any]:
        """Field values up to the ``}`` that closes node ``owner``."""
        fields: dict[str, Any] = {}
        while True:
            tok = self.lex.next()
            if tok.kind == "}":
                return fields
            if tok.kind != "id":
                raise self.src.error(tok.pos, f"expected a field name or '}}' to close "
                                              f"{owner.text} from line "
                                              f"{self.src.line(owner.pos)}, found "
                                              f"{tok.text!r}; fix the VRML syntax")
            if tok.text in _IN_OUT or tok.text in _FIELD_DECL:  # Script interface
                self.lex.expect("id", "a field type")
                name = self.lex.expect("id", "a field name").text
                if tok.text in _FIELD_DECL or self.lex.peek().text == "IS":
                    fields[name] = self.value()
            else:
                fields[tok.text] = self.value()

    def value(self) -> Any:
        """A field value: numbers, string(s), boolean, node(s), NULL or ``IS name``."""
        tok = self.lex.next()
        if tok.kind == "num":
            values = [_number(tok.text)]
            while self.lex.peek().kind == "num":
                values.append(_number(self.lex.next().text))
            return np.array(values)
        if tok.kind == "str":
            return _unquote(tok.text)
        if tok.kind == "[":
            return self.list_value(tok)
        if tok.kind == "id":
            simple = {"TRUE": True, "FALSE": False, "NULL": None}
            if tok.text in simple:
                return simple[tok.text]
            if tok.text == "IS":
                return _IsRef(self.lex.expect("id", "a PROTO field name after IS").text)
            return self.node_statement(tok)
        raise self.src.error(tok.pos, f"expected a field value, found {tok.text!r}; "
                                      "fix the VRML syntax")

    def list_value(self, open_tok: _Tok) -> Any:
        """The rest of a ``[ ... ]`` value: a numeric array, strings, booleans or nodes."""
        first = self.lex.peek()
        if first.kind == "num":
            return self.lex.number_list(open_tok.pos)
        if first.kind == "str" or first.text in ("TRUE", "FALSE"):
            items = []
            while self.lex.peek().kind != "]":
                item = self.value()
                if not isinstance(item, (str, bool)):
                    raise self.src.error(first.pos, "a list mixes strings with other values; "
                                                    "fix the VRML syntax")
                items.append(item)
            self.lex.next()
            return items
        return self.statements("]")

    def interface(self, with_values: bool) -> dict[str, Any]:
        """PROTO/EXTERNPROTO interface ``[ field SFType name value ... ]``; default values."""
        self.lex.expect("[", "'[' to open the PROTO interface")
        defaults: dict[str, Any] = {}
        while (tok := self.lex.next()).kind != "]":
            if tok.kind != "id" or tok.text not in _IN_OUT | _FIELD_DECL:
                raise self.src.error(tok.pos, f"expected field/exposedField/eventIn/eventOut "
                                              f"in a PROTO interface, found {tok.text!r}; "
                                              "fix the VRML syntax")
            self.lex.expect("id", "a field type")
            name = self.lex.expect("id", "a field name").text
            if with_values and tok.text in _FIELD_DECL:
                defaults[name] = self.value()
        return defaults

    def proto(self) -> None:
        """``PROTO name [interface] { body }``; DEF names of the body stay inside it."""
        name = self.lex.expect("id", "a PROTO name").text
        defaults = self.interface(with_values=True)
        self.lex.expect("{", f"'{{' to open the body of PROTO {name}")
        outer, self.defs = self.defs, {}
        body = self.statements("}")
        self.defs = outer
        self.protos[name] = _Proto(name, defaults, body)

    def externproto(self) -> None:
        """``EXTERNPROTO name [interface] url``: resolved from a local file when possible."""
        tok = self.lex.expect("id", "an EXTERNPROTO name")
        self.interface(with_values=False)
        urls = self.value()
        urls = [urls] if isinstance(urls, str) else urls
        if not isinstance(urls, list):
            raise self.src.error(tok.pos, f"EXTERNPROTO {tok.text} needs a url string; "
                                          "fix the VRML syntax")
        for url in urls:
            path_text, _, fragment = str(url).partition("#")
            path = _local_path(path_text, self.base_dir)
            if path is None or path in self.stack:
                continue
            protos = _parse_file(path, self.stack)[1]
            proto = protos.get(fragment) if fragment else next(iter(protos.values()), None)
            if proto is not None:
                self.protos[tok.text] = proto
                return
        self.protos[tok.text] = _Proto(tok.text, {}, urls=[str(u) for u in urls])


def _unquote(text: str) -> str:
    return re.sub(r"\\(.)", r"\1", text[1:-1])


def _substitute(value: Any, args: dict[str, Any], memo: dict[int, Any]) -> Any:
    """Copy a PROTO body, replacing ``IS`` references by ``args``; keeps USE sharing."""
    if isinstance(value, _IsRef):
        return args.get(value.name, _MISSING)
    if isinstance(value, list):
        items = (_substitute(v, args, memo) for v in value)
        return [v for v in items if v is not _MISSING]
    if not isinstance(value, _Node):
        return value
    if id(value) not in memo:
        copy = _Node(value.type, {}, value.src, value.pos, value.base_dir, value.def_name)
        memo[id(value)] = copy
        for key, item in value.fields.items():
            new = _substitute(item, args, memo)
            if new is not _MISSING:
                copy.fields[key] = new
    return memo[id(value)]


def _local_path(url: str, base_dir: Path | None) -> Path | None:
    """The existing local file a url names, or None (remote urls are never fetched)."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]+:", url) and not url.startswith("file:"):
        return None
    url = re.sub(r"^file:(//)?", "", url)
    path = Path(url) if base_dir is None else base_dir / url
    return path.resolve() if path.is_file() else None


def _read_text(path: Path) -> str:
    """The text of a (possibly gzipped) VRML file."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SonarRasterError(f"VRML file '{path}' not found; check the path") from None
    except OSError as exc:
        raise SonarRasterError(f"cannot read VRML file '{path}' ({exc.strerror}); "
                               "check the path and its permissions") from None
    if data[:2] == b"\x1f\x8b":
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError):
            raise SonarRasterError(f"{path.name}: broken gzip data; "
                                   "re-export or re-compress the file") from None
    return data.decode("utf-8", errors="replace")


def _parse_file(path: Path, stack: tuple[Path, ...]) -> tuple[list[_Node], dict[str, _Proto]]:
    """Root nodes and PROTOs of a file; ``stack`` holds the files that led to it."""
    path = path.resolve()
    parser = _Parser(_Source(path.name, _read_text(path)), path.parent, (*stack, path))
    return parser.parse(), parser.protos
