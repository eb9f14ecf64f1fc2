"""A small VRML97 reader: the subset of ``#VRML V2.0 utf8`` that model files use, as meshes.

The text is parsed into a tree of :class:`_Node` (PROTO instances already expanded, USE sharing
the DEF'd node), then walked with the current transform to make one :class:`MeshPart` per
Shape. Numeric lists (``point [...]``, ``coordIndex [...]``) are converted in bulk with numpy.

Departures from the specification that real model collections contain and that common viewers
and robotics simulators (choreonoid, OpenHRP) load are read too, each reported once per file by
a :class:`VrmlDepartureWarning` naming it and its first line (see :data:`DEPARTURES`).
"""

from __future__ import annotations

import logging
import math
import re
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputWarning, SonarRasterError
from ..scene import MeshPart

log = logging.getLogger(__name__)

#: Segments around the axis of Cylinder, Cone and Sphere (the sphere has half as many rings).
SEGMENTS = 32

_HEADER = "#VRML V2.0 utf8"
_SKIP = re.compile(r"(?:[\s,]+|#[^\n]*)*")
_TOKEN = re.compile(
    r"""(?P<num>[+-]?(?:0[xX][0-9a-fA-F]+|(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|(?i:nan)\b))
      | (?P<str>"(?:[^"\\]|\\.)*")
      | (?P<punct>[{}\[\]])
      | (?P<id>[^\x00-\x20"#'+,\-.\[\\\]{}0-9\x7f][^\x00-\x20"#',\[\\\]{}\x7f]*)""",
    re.VERBOSE | re.DOTALL,
)
_LIST_STOP = re.compile(r'[#\]{}"]')
_OVERFLOW = "gives coordinates beyond float64 (numbers too large); fix the model file"
_GROUPS = {"Group", "Transform", "Collision", "Anchor", "Billboard"}
_IN_OUT = {"eventIn", "eventOut", "inputOnly", "outputOnly"}
_FIELD_DECL = {"field", "exposedField", "initializeOnly", "inputOutput"}
_MISSING = object()

#: The departures from VRML97 this reader accepts, found in public robot and environment model
#: collections (choreonoid, OpenHRP3, rtmros_choreonoid), with what is done about each.
DEPARTURES = {
    "no-header": "no '#VRML V2.0 utf8' header line; read as VRML97",
    "late-header": "the '#VRML V2.0 utf8' header is not on the first line; read as VRML97",
    "def-no-name": "DEF without a name before a node type; read as an unnamed node",
    "nan": "'nan' numbers (not numbers, e.g. normals of degenerate faces); faces with a NaN "
    "corner are dropped",
    "size": "a Box, Cone, Cylinder or Sphere size that is not > 0 (it would be inside out or "
    "empty); the shape is left out",
}


class VrmlDepartureWarning(InputWarning):
    """A VRML file departs from the specification in a way this reader repairs (one per kind)."""


@dataclass
class _Source:
    """A parsed text: its name for messages and the offsets of its line breaks."""

    name: str
    text: str
    _breaks: np.ndarray | None = None
    departures: dict[str, list[int]] = field(default_factory=dict)

    def line(self, pos: int) -> int:
        """1-based line number of character offset ``pos``."""
        if self._breaks is None:
            self._breaks = np.array([m.start() for m in re.finditer("\n", self.text)], dtype=int)
        return int(np.searchsorted(self._breaks, pos)) + 1

    def error(self, pos: int, message: str) -> SonarRasterError:
        """Make a one-line error ``name:line: message`` located at ``pos``."""
        return SonarRasterError(f"{self.name}:{self.line(pos)}: {message}")

    def depart(self, pos: int, kind: str, count: int = 1) -> None:
        """Note a departure of ``kind`` (a key of :data:`DEPARTURES`) at ``pos``."""
        first, seen = self.departures.get(kind, [pos, 0])
        self.departures[kind] = [min(first, pos), seen + count]

    def warn(self) -> None:
        """Emit one warning per departure kind noted so far, then forget them."""
        for kind, (pos, count) in sorted(self.departures.items(), key=lambda kv: kv[1][0]):
            places = f" ({count} places)" if count > 1 else ""
            warnings.warn(
                f"{self.name}:{self.line(pos)}: departs from VRML97: {DEPARTURES[kind]}{places}",
                VrmlDepartureWarning,
                stacklevel=4,
            )
        self.departures.clear()


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

    @property
    def shown(self) -> str:
        """The token as quoted in messages."""
        return "end of file" if self.kind == "eof" else repr(self.text)


class _Lexer:
    """Tokens of a VRML text, with numeric lists read in one numpy call."""

    def __init__(self, src: _Source) -> None:
        self.src, self.text, self.pos = src, src.text, 0
        self._peeked: _Tok | None = None

    def peek(self) -> _Tok:
        """Return the next token without consuming it."""
        if self._peeked is None:
            pos = _SKIP.match(self.text, self.pos).end()  # type: ignore[union-attr]
            if pos >= len(self.text):
                self._peeked = _Tok("eof", "", len(self.text.rstrip()))
            else:
                m = _TOKEN.match(self.text, pos)
                if m is None:
                    raise self.src.error(
                        pos, f"unexpected character {self.text[pos]!r}; fix the VRML syntax"
                    )
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
            raise self.src.error(
                tok.pos, f"expected {what}, found {tok.shown}; fix the VRML syntax"
            )
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
                raise self.src.error(
                    m.start(),
                    f"expected a number or ']', found "
                    f"{m.group()!r}; close the list opened on "
                    f"line {self.src.line(open_pos)}",
                )
        words = "".join(pieces).replace(",", " ").split()
        try:
            values = np.array(words, dtype=np.float64)
        except ValueError:
            values = self._slow_numbers(words, start)
        finite = np.isfinite(values)
        if not np.all(finite | np.isnan(values)):
            word = words[int(np.argmin(finite | np.isnan(values)))]
            raise self.src.error(self.text.find(word, start), _not_finite(word))
        if not np.all(finite):
            word = words[int(np.argmin(finite))]
            self.src.depart(self.text.find(word, start), "nan", int(np.sum(~finite)))
        return values

    def _slow_numbers(self, words: list[str], start: int) -> np.ndarray:
        """Convert hexadecimal integers, or raise at the first word that is not a number."""
        out = np.empty(len(words))
        for k, word in enumerate(words):
            m = _TOKEN.fullmatch(word)
            if m is None or m.lastgroup != "num":
                raise self.src.error(
                    self.text.find(word, start),
                    f"expected a number, found {word!r}; fix the VRML syntax",
                )
            out[k] = _number(word)
        return out


def _lenient() -> Any:
    """No floating-point warnings: large finite numbers may overflow; results are checked."""
    return np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore")


def _number(text: str) -> float:
    try:
        return float(int(text, 16)) if text.lstrip("+-")[:2] in ("0x", "0X") else float(text)
    except OverflowError:  # a hexadecimal integer beyond float64
        return math.inf


def _not_finite(word: str) -> str:
    return f"the number {word[:40]!r} is not a finite float64 (|x| < 1.8e308); fix the model file"


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
        if text.startswith("#VRML V1.0"):
            raise self.src.error(0, "VRML 1.0 is not supported; convert the file to VRML97")
        headless = not text.startswith(_HEADER)
        if headless:
            late = re.match(r"(?:[ \t]*(?:#[^\n]*)?\r?\n)+[ \t]*" + re.escape(_HEADER), text)
            self.src.depart(0, "late-header" if late else "no-header")
        self.lex.pos = len(self.src.text) - len(text)  # skip a byte-order mark
        try:
            return self.statements("eof")  # the header line is a comment
        except RecursionError:
            raise self.src.error(
                self.lex.pos, "nodes are nested too deeply; flatten the hierarchy"
            ) from None
        except SonarRasterError as exc:
            if headless and "no-header" in self.src.departures:
                raise SonarRasterError(
                    f"{self.src.name}: not a VRML97 file (no '{_HEADER}' header line, and not "
                    f"readable without one: {exc})"
                ) from None
            raise

    def statements(self, end: str) -> list[_Node]:
        """Nodes up to (and consuming) a token of kind ``end``; PROTO and ROUTE are absorbed."""
        nodes = []
        while self.lex.peek().kind != end:
            tok = self.lex.next()
            if tok.kind != "id":
                closing = {"eof": "end of file", "]": "']'", "}": "'}'"}[end]
                raise self.src.error(
                    tok.pos,
                    f"expected a node or {closing}, found {tok.shown}; fix the VRML syntax",
                )
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
                raise self.src.error(
                    name.pos, f"USE {name.text} before any DEF {name.text}; define the node first"
                )
            return self.defs[name.text]
        def_name = None
        if tok.text == "DEF":
            name = self.lex.expect("id", "a name after DEF")
            if self.lex.peek().kind == "{":  # "DEF Transform {": the name was left out
                self.src.depart(name.pos, "def-no-name")
                tok = name
            else:
                def_name = name.text
                tok = self.lex.expect("id", f"a node type after DEF {def_name}")
        node = self.node(tok, def_name)
        if def_name is not None:
            self.defs[def_name] = node
        return node

    def node(self, tok: _Tok, def_name: str | None) -> _Node | None:
        """Parse node ``tok {...}``; a PROTO instance expands to (a copy of) its body."""
        self.lex.expect("{", f"'{{' after {tok.text}")
        fields = self.fields(tok)
        proto = self.protos.get(tok.text)
        if proto is None:
            return _Node(tok.text, fields, self.src, tok.pos, self.base_dir, def_name)
        if proto.urls is not None:
            raise self.src.error(
                tok.pos,
                f"EXTERNPROTO {tok.text} has no local file among "
                f"{proto.urls}; put that file next to this one",
            )
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
                raise self.src.error(
                    tok.pos,
                    f"expected a field name or '}}' to close "
                    f"{owner.text} from line "
                    f"{self.src.line(owner.pos)}, found "
                    f"{tok.shown}; fix the VRML syntax",
                )
            if tok.text in _IN_OUT or tok.text in _FIELD_DECL:  # Script interface
                self.lex.expect("id", "a field type")
                name = self.lex.expect("id", "a field name").text
                if tok.text in _FIELD_DECL or self.lex.peek().text == "IS":
                    fields[name] = self.value()
            else:
                fields[tok.text] = self.value()

    def value(self) -> Any:
        """Parse a field value: numbers, string(s), boolean, node(s), NULL or ``IS name``."""
        tok = self.lex.next()
        if tok.kind == "num":
            words = [tok]
            while self.lex.peek().kind == "num":
                words.append(self.lex.next())
            values = [_number(word.text) for word in words]
            for word, value in zip(words, values, strict=True):
                if math.isnan(value):
                    self.src.depart(word.pos, "nan")
                elif not math.isfinite(value):
                    raise self.src.error(word.pos, _not_finite(word.text))
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
        raise self.src.error(
            tok.pos, f"expected a field value, found {tok.shown}; fix the VRML syntax"
        )

    def list_value(self, open_tok: _Tok) -> Any:
        """Parse the rest of a ``[ ... ]`` value: numbers, strings, booleans or nodes."""
        first = self.lex.peek()
        if first.kind == "num":
            return self.lex.number_list(open_tok.pos)
        if first.kind == "str" or first.text in ("TRUE", "FALSE"):
            items = []
            while self.lex.peek().kind != "]":
                item = self.value()
                if not isinstance(item, (str, bool)):
                    raise self.src.error(
                        first.pos, "a list mixes strings with other values; fix the VRML syntax"
                    )
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
                raise self.src.error(
                    tok.pos,
                    f"expected field/exposedField/eventIn/eventOut "
                    f"in a PROTO interface, found {tok.shown}; "
                    "fix the VRML syntax",
                )
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
            raise self.src.error(
                tok.pos, f"EXTERNPROTO {tok.text} needs a url string; fix the VRML syntax"
            )
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
    """Return the existing local file a url names, else None (never fetches remote urls)."""
    if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]+:", url) and not url.startswith("file:"):
        return None
    url = re.sub(r"^file:(//)?", "", url)
    path = Path(url) if base_dir is None else base_dir / url
    return path.resolve() if path.is_file() else None


def _read_text(path: Path) -> str:
    """Read the text of a (possibly gzipped) VRML file."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SonarRasterError(f"VRML file '{path}' not found; check the path") from None
    except OSError as exc:
        raise SonarRasterError(
            f"cannot read VRML file '{path}' ({exc.strerror}); check the path and its permissions"
        ) from None
    if data[:2] == b"\x1f\x8b":
        data = _gunzip(data, path.name, MAX_TEXT_BYTES)
    return data.decode("utf-8", errors="replace")


#: Largest VRML text read (after decompression): text of this size parses into several times
#: as much memory, far beyond any model a side-scan scene holds.
MAX_TEXT_BYTES = 1 << 30


def _gunzip(data: bytes, name: str, limit: int) -> bytes:
    """Decompress every gzip member of ``data``, refusing to grow past ``limit`` bytes."""
    out, total = [], 0
    rest = data
    try:
        while rest:
            inflater = zlib.decompressobj(wbits=31)
            chunk = inflater.decompress(rest, limit + 1 - total)
            total += len(chunk)
            out.append(chunk)
            if total > limit or inflater.unconsumed_tail:
                raise SonarRasterError(
                    f"{name}: decompresses to more than {limit >> 20} MiB of text; "
                    "not a model file this tool can load"
                )
            if not inflater.eof:
                raise zlib.error("truncated gzip stream")
            rest = inflater.unused_data
            if rest and rest[:2] != b"\x1f\x8b":
                break  # trailing bytes after the last member, as gzip itself ignores
    except (OSError, EOFError, zlib.error):
        raise SonarRasterError(
            f"{name}: broken gzip data; re-export or re-compress the file"
        ) from None
    return b"".join(out)


def _parse_file(path: Path, stack: tuple[Path, ...]) -> tuple[list[_Node], dict[str, _Proto]]:
    """Root nodes and PROTOs of a file; ``stack`` holds the files that led to it."""
    path = path.resolve()
    parser = _Parser(_Source(path.name, _read_text(path)), path.parent, (*stack, path))
    roots = parser.parse()
    parser.src.warn()
    return roots, parser.protos


def _numbers(node: _Node, name: str, default: Any = None, width: int = 1) -> np.ndarray:
    """Numeric field ``name`` as a flat float64 array whose size is a multiple of ``width``."""
    value = node.fields.get(name, default)
    if value is None or (isinstance(value, list) and not value):
        return np.zeros(0)
    if not isinstance(value, np.ndarray) or value.size % width:
        raise node.src.error(
            node.pos,
            f"{node.type} field '{name}' needs numbers in groups of {width}; fix the model file",
        )
    return value.ravel()


def _vector(node: _Node, name: str, default: tuple[float, ...]) -> np.ndarray:
    """Single-valued numeric field (SFVec3f, SFRotation, SFFloat...) of ``len(default)``."""
    value = _numbers(node, name, np.array(default, dtype=np.float64))
    if value.size != len(default):
        raise node.src.error(
            node.pos,
            f"{node.type} field '{name}' needs {len(default)} "
            f"number(s), got {value.size}; fix the model file",
        )
    return value


class _NoSize(Exception):
    """A primitive's size field that is not > 0 (noted as a departure; the shape left out)."""


def _size(node: _Node, name: str, default: tuple[float, ...]) -> np.ndarray:
    """A size field (Box size, radius, height): every number > 0, as VRML97 requires."""
    value = _vector(node, name, default)
    if not np.all(value > 0):
        raise _NoSize
    return value


def _flag(node: _Node, name: str, default: bool) -> bool:
    value = node.fields.get(name, default)
    if not isinstance(value, bool):
        raise node.src.error(
            node.pos, f"{node.type} field '{name}' must be TRUE or FALSE; fix the model file"
        )
    return value


def _children(node: _Node, name: str) -> list[_Node]:
    value = node.fields.get(name)
    if value is None or isinstance(value, _Node):
        return [] if value is None else [value]
    if isinstance(value, list) and all(isinstance(v, _Node) for v in value):
        return value
    raise node.src.error(
        node.pos, f"{node.type} field '{name}' must hold nodes; fix the model file"
    )


def _rotation(axis_angle: np.ndarray) -> np.ndarray:
    """3×3 matrix of a VRML rotation ``(x, y, z, angle in radians)``."""
    axis, angle = axis_angle[:3], axis_angle[3]
    norm = np.linalg.norm(axis)
    if norm == 0.0:
        return np.eye(3)
    x, y, z = axis / norm
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def _transform_matrix(node: _Node) -> np.ndarray:
    """4×4 matrix of a Transform node: ``T·C·R·SR·S·(-SR)·(-C)`` (VRML97 §6.52)."""
    center = _vector(node, "center", (0.0, 0.0, 0.0))
    orient = _rotation(_vector(node, "scaleOrientation", (0.0, 0.0, 1.0, 0.0)))
    linear = (
        _rotation(_vector(node, "rotation", (0.0, 0.0, 1.0, 0.0)))
        @ orient
        @ np.diag(_vector(node, "scale", (1.0, 1.0, 1.0)))
        @ orient.T
    )
    matrix = np.eye(4)
    matrix[:3, :3] = linear
    matrix[:3, 3] = _vector(node, "translation", (0.0, 0.0, 0.0)) + center - linear @ center
    return matrix


def _distinct(faces: np.ndarray) -> np.ndarray:
    """Mask of triangles, shape (m,), whose three corner indices differ."""
    a, b, c = faces.T
    return (a != b) & (b != c) & (a != c)


def _fan(index: np.ndarray) -> np.ndarray:
    """Fan triangles, shape (m, 3), of ``-1``-separated polygons; repeated corners dropped."""
    index = np.asarray(index, dtype=np.int64)
    if index.size == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if index[-1] != -1:
        index = np.append(index, -1)
    sep = index == -1
    polygon = np.cumsum(sep) - sep
    starts = np.flatnonzero(np.r_[True, sep[:-1]])
    corner = np.arange(index.size) - starts[polygon]
    last = np.flatnonzero((corner >= 2) & ~sep)
    faces = np.stack([index[starts[polygon[last]]], index[last - 1], index[last]], axis=1)
    return faces[_distinct(faces)]


def _indexed_face_set(node: _Node) -> tuple[np.ndarray, ...]:
    coord = node.fields.get("coord")
    points = _numbers(coord, "point", width=3) if isinstance(coord, _Node) else np.zeros(0)
    points = points.reshape(-1, 3)
    index = _numbers(node, "coordIndex")
    bad = index[(index < -1) | (index >= len(points)) | (index != np.round(index))]
    if bad.size:
        raise node.src.error(
            node.pos,
            f"IndexedFaceSet coordIndex {bad[0]:g} is outside its "
            f"{len(points)} points; fix the model file",
        )
    convex = _flag(node, "convex", True)
    # triangulate the places in coordIndex, so that a triangle's corners name their polygon
    # and their entries of colorIndex too
    place = np.where(index == -1, -1, np.arange(index.size))
    vertex = np.maximum(index, 0).astype(np.int64)
    corners = _fan(place) if convex else _ear_cut(points[vertex], place)
    corners = corners[_distinct(vertex[corners])]
    corners = corners[_finite(points, vertex[corners])]
    faces = vertex[corners]
    grey = _face_colours(node, index, corners)
    faces = faces if _flag(node, "ccw", True) else faces[:, [0, 2, 1]]
    return (points, faces) if grey is None else (points, faces, grey)


def _colour_greys(node: _Node) -> np.ndarray | None:
    """The RGB means of a geometry's ``color`` node, or None when it has no colours."""
    colour = node.fields.get("color")
    if not isinstance(colour, _Node):
        return None
    grey = _numbers(colour, "color", width=3).reshape(-1, 3).mean(axis=1)
    return grey if grey.size else None


def _face_colours(node: _Node, index: np.ndarray, corners: np.ndarray) -> np.ndarray | None:
    """Grey (RGB mean) per triangle from an IndexedFaceSet's ``color`` node, or None.

    VRML97: the colours replace the Material's diffuse colour; per vertex (``colorPerVertex``
    TRUE, the default) through ``colorIndex`` like ``coordIndex`` (or ``coordIndex`` itself when
    it is empty), a triangle taking its corners' mean; per face through ``colorIndex`` (or in
    order). ``corners`` are the triangles' places in ``coordIndex``. Indices that do not fit
    the colours are a warning, and the Material's colour is used.
    """
    grey = _colour_greys(node)
    if grey is None:
        return None
    lookup = _numbers(node, "colorIndex")
    problem, wanted = None, np.zeros(0)
    if _flag(node, "colorPerVertex", True):
        if lookup.size and lookup.size < index.size:
            problem = f"colorIndex has {lookup.size} entries for {index.size} in coordIndex"
        else:
            wanted = (lookup if lookup.size else index)[corners]
    else:
        separators = index == -1
        polygon = (np.cumsum(separators) - separators)[corners[:, 0]]
        if lookup.size and polygon.size and polygon.max() >= lookup.size:
            problem = f"colorIndex has {lookup.size} entries for {int(polygon.max()) + 1} faces"
        else:
            wanted = lookup[polygon] if lookup.size else polygon
    outside = wanted[(wanted < 0) | (wanted >= grey.size)]
    if problem is None and outside.size:
        problem = f"colour index {outside[0]:g} is outside its {grey.size} colours"
    if problem is not None:
        warnings.warn(
            f"{node.src.name}:{node.src.line(node.pos)}: IndexedFaceSet {problem}; the "
            "Material's colour is used instead",
            InputWarning,
            stacklevel=2,
        )
        return None
    picked = grey[wanted.astype(np.int64)]
    return picked.mean(axis=1) if picked.ndim == 2 else picked


def _ear_cut(points: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Triangles of ``-1``-separated polygons that may be concave (``convex FALSE``).

    Polygons are grouped by corner count; a convex one (every corner turning the way of its
    Newell normal) is fanned, a concave one projected on the plane of its normal's largest
    component and cut into ears (mapbox-earcut), each triangle turned as the polygon winds.
    """
    import mapbox_earcut

    index = np.asarray(index, dtype=np.int64)
    polygons = [p[p >= 0] for p in np.split(index, np.flatnonzero(index == -1))]
    groups: dict[int, list[np.ndarray]] = {}
    for polygon in polygons:
        groups.setdefault(len(polygon), []).append(polygon)
    out = [np.zeros((0, 3), dtype=np.int64)]
    for size, group in groups.items():
        if size < 3:
            continue
        block = np.array(group)
        corners = points[block]
        ahead = np.roll(corners, -1, axis=1)
        normal = np.cross(corners, ahead).sum(axis=1)  # Newell: twice the area vector
        edge = ahead - corners
        with np.errstate(invalid="ignore"):
            turn = np.einsum("pkc,pc->pk", np.cross(edge, np.roll(edge, -1, axis=1)), normal)
        convex = np.all(turn >= 0.0, axis=1) | (size == 3)
        ends = np.full((int(convex.sum()), 1), -1)
        out.append(_fan(np.hstack([block[convex], ends]).ravel()))
        for polygon, spot, n in zip(block[~convex], corners[~convex], normal[~convex], strict=True):
            keep = [k for k in range(3) if k != int(np.argmax(np.abs(n)))]
            ears = mapbox_earcut.triangulate_float64(
                np.ascontiguousarray(spot[:, keep]), np.array([size], np.uint32)
            ).reshape(-1, 3)
            tri = spot[ears]
            back = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) @ n < 0
            out.append(polygon[np.where(back[:, None], ears[:, [0, 2, 1]], ears)])
    faces = np.concatenate(out)
    return faces[_distinct(faces)]


def _finite_faces(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Drop faces with a NaN corner ('nan' in the file); NaN points become 0 (unused)."""
    return faces[_finite(points, faces)] if len(faces) else faces


def _finite(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Mask of the faces whose corners are finite; NaN points become 0 (unused)."""
    bad = ~np.all(np.isfinite(points), axis=1)
    if not bad.any() or not len(faces):
        return np.ones(len(faces), dtype=bool)
    points[bad] = 0.0
    return ~bad[faces].any(axis=1)


def _whole(node: _Node, name: str, default: int) -> int:
    """An integer field's value; a NaN or infinite one is an error naming the field."""
    value = float(_vector(node, name, (default,))[0])
    if not math.isfinite(value):
        raise node.src.error(node.pos, f"{node.type} {name} must be a whole number, got {value}")
    return int(value)


def _elevation_grid(node: _Node) -> tuple[np.ndarray, ...]:
    nx = _whole(node, "xDimension", 0)
    nz = _whole(node, "zDimension", 0)
    height = _numbers(node, "height")
    if nx < 2 or nz < 2 or height.size != nx * nz:
        raise node.src.error(
            node.pos,
            "ElevationGrid needs xDimension, zDimension >= 2 and "
            "xDimension*zDimension heights; fix the model file",
        )
    x, z = np.meshgrid(
        np.arange(nx) * _vector(node, "xSpacing", (1.0,))[0],
        np.arange(nz) * _vector(node, "zSpacing", (1.0,))[0],
    )
    vertices = np.stack([x.ravel(), height, z.ravel()], axis=1)
    a = (np.arange(nz - 1)[:, None] * nx + np.arange(nx - 1)).ravel()
    b, c, d = a + nx, a + nx + 1, a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    quad = np.tile(np.arange(a.size), 2)  # each triangle's grid cell
    keep = _finite(vertices, faces)
    faces, quad = faces[keep], quad[keep]
    grey = _grid_colours(node, faces, quad, nx, nz)
    faces = faces if _flag(node, "ccw", True) else faces[:, [0, 2, 1]]
    return (vertices, faces) if grey is None else (vertices, faces, grey)


def _grid_colours(
    node: _Node, faces: np.ndarray, quad: np.ndarray, nx: int, nz: int
) -> np.ndarray | None:
    """Grey per triangle from an ElevationGrid's ``color`` node, or None.

    VRML97: one colour per grid point (``colorPerVertex`` TRUE), a triangle taking its
    corners' mean, or one per cell, x fastest. Too few colours are a warning, and the
    Material's colour is used.
    """
    grey = _colour_greys(node)
    if grey is None:
        return None
    per_vertex = _flag(node, "colorPerVertex", True)
    needed = nx * nz if per_vertex else (nx - 1) * (nz - 1)
    if grey.size < needed:
        warnings.warn(
            f"{node.src.name}:{node.src.line(node.pos)}: ElevationGrid has {grey.size} colours "
            f"for {needed} {'points' if per_vertex else 'cells'}; the Material's colour is "
            "used instead",
            InputWarning,
            stacklevel=2,
        )
        return None
    return grey[faces].mean(axis=1) if per_vertex else grey[quad]


def _box(node: _Node) -> tuple[np.ndarray, np.ndarray]:
    half = _size(node, "size", (2.0, 2.0, 2.0)) / 2
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    faces = [
        [0, 1, 3],
        [0, 3, 2],
        [4, 7, 5],
        [4, 6, 7],
        [0, 4, 5],
        [0, 5, 1],
        [2, 7, 6],
        [2, 3, 7],
        [0, 2, 6],
        [0, 6, 4],
        [1, 7, 3],
        [1, 5, 7],
    ]
    return signs * half, np.array(faces, dtype=np.int64)


def _lathe(
    profile: list[tuple[float, float]],
    bottom: bool,
    top: bool,
    side: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Surface of revolution about +y from (radius, y) pairs listed bottom to top."""
    theta = 2 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    vertices: list[np.ndarray] = []
    rings: list[np.ndarray] = []
    count = 0
    for radius, y in profile:
        n = 1 if radius == 0 else SEGMENTS  # a pole is one vertex
        vertices.append(
            np.stack([radius * np.sin(theta), np.full(SEGMENTS, y), radius * np.cos(theta)], 1)[:n]
        )
        rings.append(count + np.arange(SEGMENTS) % n)
        count += n
    faces: list[np.ndarray] = []
    if side:
        for low, up in zip(rings[:-1], rings[1:], strict=True):
            low1, up1 = np.roll(low, -1), np.roll(up, -1)
            faces += [np.stack([low, low1, up1], 1), np.stack([low, up1, up], 1)]
    for ring, y, wanted, is_top in (
        (rings[0], profile[0][1], bottom, False),
        (rings[-1], profile[-1][1], top, True),
    ):
        if wanted:
            vertices.append(np.array([[0.0, y, 0.0]]))
            pair = (ring, np.roll(ring, -1)) if is_top else (np.roll(ring, -1), ring)
            faces.append(np.stack([np.full(SEGMENTS, count), *pair], 1))
            count += 1
    tri = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(vertices), tri[_distinct(tri)].astype(np.int64)


def _cylinder(node: _Node) -> tuple[np.ndarray, np.ndarray]:
    r, h = _size(node, "radius", (1.0,))[0], _size(node, "height", (2.0,))[0]
    return _lathe(
        [(r, -h / 2), (r, h / 2)],
        _flag(node, "bottom", True),
        _flag(node, "top", True),
        _flag(node, "side", True),
    )


def _cone(node: _Node) -> tuple[np.ndarray, np.ndarray]:
    r, h = _size(node, "bottomRadius", (1.0,))[0], _size(node, "height", (2.0,))[0]
    return _lathe(
        [(r, -h / 2), (0.0, h / 2)], _flag(node, "bottom", True), False, _flag(node, "side", True)
    )


def _sphere(node: _Node) -> tuple[np.ndarray, np.ndarray]:
    r = _size(node, "radius", (1.0,))[0]
    phi = np.pi * np.arange(SEGMENTS // 2, -1, -1) / (SEGMENTS // 2)
    radii = r * np.sin(phi)
    radii[[0, -1]] = 0.0
    return _lathe(list(zip(radii, r * np.cos(phi), strict=True)), False, False)


def _per_spine(values: np.ndarray, n: int) -> np.ndarray:
    """One row of ``values`` per spine point: the rows given, the last one repeated."""
    return values[np.minimum(np.arange(n), len(values) - 1)]


def _unit(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows scaled to length 1, and which rows had a length to scale (the rest stay 0)."""
    norm = np.linalg.norm(vectors, axis=1)
    ok = norm > 1e-12 * max(float(norm.max(initial=0.0)), 1e-300)
    out = np.zeros_like(vectors)
    out[ok] = vectors[ok] / norm[ok, None]
    return out, ok


def _spine_frames(spine: np.ndarray) -> np.ndarray:
    """Per spine point the cross-section plane's axes as rows X, Y, Z, shape (n, 3, 3).

    VRML97 §6.18: Y along the spine (the chord of the neighbours; a closed spine joins its
    ends), Z the normal of the spine's bend at the point (at an open end its neighbour's),
    flipped to agree with the previous one; where the spine does not bend, the previous Z;
    a straight spine takes the rotation of +y onto it applied to +z. X = Y × Z.
    """
    n = len(spine)
    closed = n > 2 and np.allclose(spine[0], spine[-1])
    ahead = np.vstack([spine[1:], spine[-1:]])
    behind = np.vstack([spine[:1], spine[:-1]])
    if closed:
        ahead[-1], behind[0] = spine[1], spine[-2]
    y, y_ok = _unit(ahead - behind)
    for i in range(n):  # coincident points: the nearest direction before, else after
        if not y_ok[i]:
            near = np.flatnonzero(y_ok)
            y[i] = y[near[np.argmin(np.abs(near - i))]] if near.size else (0.0, 1.0, 0.0)
    z = np.cross(ahead - spine, behind - spine)
    if not closed:
        z[0], z[-1] = z[min(1, n - 1)], z[max(n - 2, 0)]
    z, z_ok = _unit(z)
    if not z_ok.any():  # a straight spine: +y turned onto it takes +z along
        axis = np.cross((0.0, 1.0, 0.0), y[0])
        angle = math.atan2(float(np.linalg.norm(axis)), float(y[0][1]))
        if np.linalg.norm(axis) < 1e-12:
            axis = np.array([1.0, 0.0, 0.0])
        z[:] = _rotation(np.r_[axis, angle]) @ np.array([0.0, 0.0, 1.0])
    else:
        first = int(np.argmax(z_ok))
        z[:first] = z[first]
        for i in range(first + 1, n):
            if not z_ok[i]:
                z[i] = z[i - 1]
            elif float(z[i] @ z[i - 1]) < 0.0:
                z[i] = -z[i]
    return np.stack([np.cross(y, z), y, z], axis=1)


def _extrusion(node: _Node) -> tuple[np.ndarray, np.ndarray]:
    """Extrusion (VRML97 §6.18), swept and capped.

    The cross-section, scaled and turned by ``orientation``, is placed in each spine point's
    plane (:func:`_spine_frames`) and joined to the next; the caps are fanned. A closed, capped
    extrusion is turned to face outward whatever the section's direction (files often get
    ``ccw`` wrong and rely on ``solid FALSE``); an open one follows ``ccw``.
    """
    spine = _numbers(node, "spine", np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0]), 3).reshape(-1, 3)
    default = np.array([1.0, 1.0, 1.0, -1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
    section = _numbers(node, "crossSection", default, 2).reshape(-1, 2)
    scale = _numbers(node, "scale", np.array([1.0, 1.0]), 2).reshape(-1, 2)
    orientation = _numbers(node, "orientation", np.array([0.0, 0.0, 1.0, 0.0]), 4)
    n, m = len(spine), len(section)
    if n < 2 or m < 2 or not len(scale) or not orientation.size:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    turns = [_rotation(r) for r in _per_spine(orientation.reshape(-1, 4), n)]
    flat = np.stack([section[:, 0], np.zeros(m), section[:, 1]], axis=1)
    frames = _spine_frames(spine)
    rings = []
    for i, (sx, sz) in enumerate(_per_spine(scale, n)):
        local = flat * np.array([sx, 1.0, sz])
        rings.append(spine[i] + (local @ turns[i].T) @ frames[i])
    vertices = np.concatenate(rings)
    ring = np.arange(m)
    a = (np.arange(n - 1)[:, None] * m + ring[:-1]).ravel()
    b, c, d = a + 1, a + m + 1, a + m
    faces = [np.stack([a, c, d], 1), np.stack([a, b, c], 1)]
    closed = np.allclose(section[0], section[-1]) and m >= 4
    cap = ring[:-1] if closed else ring  # a closed section's last point is its first
    if _flag(node, "beginCap", True) and len(cap) >= 3:
        faces.append(_fan(cap)[:, [0, 2, 1]])
    if _flag(node, "endCap", True) and len(cap) >= 3:
        faces.append(_fan((n - 1) * m + cap))
    tri = np.concatenate(faces)
    tri = _finite_faces(vertices, tri[_distinct(tri)])
    if closed and _flag(node, "beginCap", True) and _flag(node, "endCap", True) and len(tri):
        p0, p1, p2 = (vertices[tri[:, k]] for k in range(3))
        volume = float(np.einsum("ij,ij->i", p0, np.cross(p1, p2)).sum())  # 6 × signed volume
        return vertices, tri if volume >= 0.0 else tri[:, [0, 2, 1]]
    return vertices, tri if _flag(node, "ccw", True) else tri[:, [0, 2, 1]]


#: Geometry nodes without a surface (lines, points): left out without a warning.
_NO_SURFACE = {"IndexedLineSet", "PointSet"}

_GEOMETRY = {
    "IndexedFaceSet": _indexed_face_set,
    "ElevationGrid": _elevation_grid,
    "Box": _box,
    "Cylinder": _cylinder,
    "Cone": _cone,
    "Sphere": _sphere,
    "Extrusion": _extrusion,
}


def _reflectivity(shape: _Node) -> float:
    """Mean Material diffuseColor (VRML default 0.8); 0.5 without Appearance or Material."""
    appearance = shape.fields.get("appearance")
    material = appearance.fields.get("material") if isinstance(appearance, _Node) else None
    if not isinstance(material, _Node):
        return 0.5
    return float(_vector(material, "diffuseColor", (0.8, 0.8, 0.8)).mean())


class _Walker:
    """Walks root nodes with the current transform and collects one MeshPart per Shape."""

    def __init__(self, stem: str, stack: tuple[Path, ...]) -> None:
        self.stem, self.stack = stem, list(stack)
        self.parts: list[MeshPart] = []
        # (points, faces) or (points, faces, grey per face) of each geometry node, built once
        self._meshes: dict[int, tuple[np.ndarray, ...] | None] = {}
        self._inlines: dict[Path, list[_Node]] = {}
        self._unsupported: set[str] = set()  # geometry types (and "size") already warned about

    def walk(self, nodes: list[_Node], matrix: np.ndarray, name: str | None) -> list[MeshPart]:
        """Visit ``nodes`` under ``matrix``; ``name`` is the nearest ancestor DEF name."""
        for node in nodes:
            self.visit(node, matrix, name)
        return self.parts

    def visit(self, node: _Node, matrix: np.ndarray, name: str | None) -> None:
        """Dispatch on the node type; unknown nodes are skipped."""
        inner = node.def_name or name
        if node.type in _GROUPS:
            if node.type == "Transform":
                with _lenient():
                    matrix = matrix @ _transform_matrix(node)
                if not np.all(np.isfinite(matrix)):
                    raise node.src.error(node.pos, f"Transform {_OVERFLOW}")
            self.walk(_children(node, "children"), matrix, inner)
        elif node.type in ("Switch", "LOD"):
            key = "choice" if node.type == "Switch" else "level"
            options = _children(node, key if key in node.fields else "children")
            pick = _whole(node, "whichChoice", -1) if node.type == "Switch" else 0
            if 0 <= pick < len(options):
                self.visit(options[pick], matrix, inner)
        elif node.type == "Shape":
            self.shape(node, matrix, name)
        elif node.type == "Inline":
            self.inline(node, matrix, inner)
        else:
            log.debug("%s:%d: skipping %s node", node.src.name, node.src.line(node.pos), node.type)

    def shape(self, node: _Node, matrix: np.ndarray, name: str | None) -> None:
        """Append the Shape's geometry as a MeshPart in world coordinates."""
        geometry = node.fields.get("geometry")
        if not isinstance(geometry, _Node):
            return
        if id(geometry) not in self._meshes:
            build = _GEOMETRY.get(geometry.type)
            if build is None and geometry.type not in self._unsupported | _NO_SURFACE:
                self._unsupported.add(geometry.type)
                warnings.warn(
                    f"{geometry.src.name}:{geometry.src.line(geometry.pos)}: {geometry.type} "
                    f"geometry is not read and is left out (read: {', '.join(_GEOMETRY)}); "
                    "export the model as a triangle mesh to keep it",
                    InputWarning,
                    stacklevel=2,
                )
            with _lenient():
                try:
                    self._meshes[id(geometry)] = None if build is None else build(geometry)
                except _NoSize:
                    self._meshes[id(geometry)] = None
                    if "size" not in self._unsupported:  # once per file, like a departure
                        self._unsupported.add("size")
                        where = f"{geometry.src.name}:{geometry.src.line(geometry.pos)}"
                        warnings.warn(
                            f"{where}: departs from VRML97: {DEPARTURES['size']}",
                            VrmlDepartureWarning,
                            stacklevel=2,
                        )
        mesh = self._meshes[id(geometry)]
        if mesh is None or not len(mesh[1]):
            return
        with _lenient():
            vertices = mesh[0] @ matrix[:3, :3].T + matrix[:3, 3]
            # a Color node's colours replace the Material's diffuse colour (VRML97)
            reflectivity = _reflectivity(node) if len(mesh) < 3 else mesh[2]
        if not (np.all(np.isfinite(vertices)) and np.all(np.isfinite(reflectivity))):
            raise node.src.error(node.pos, f"{geometry.type} {_OVERFLOW}")
        mirrored = np.linalg.slogdet(matrix[:3, :3])[0] < 0  # the sign, without overflow
        faces = mesh[1][:, ::-1] if mirrored else mesh[1]
        name = node.def_name or geometry.def_name or name or f"{self.stem}_{len(self.parts)}"
        self.parts.append(MeshPart(vertices, np.array(faces, dtype=np.int64), reflectivity, name))

    def inline(self, node: _Node, matrix: np.ndarray, name: str | None) -> None:
        """Walk the file named by the Inline's ``url``, relative to the including file."""
        urls = node.fields.get("url", [])
        urls = [urls] if isinstance(urls, str) else list(urls)
        path = next(filter(None, (_local_path(str(u), node.base_dir) for u in urls)), None)
        if path is None:
            raise node.src.error(
                node.pos,
                f"Inline file {', '.join(map(repr, urls)) or '(none)'}"
                f" not found next to {node.src.name}; "
                "put it there or fix the url",
            )
        if path in self.stack:
            raise node.src.error(
                node.pos, f"Inline '{path.name}' includes itself; remove the cycle"
            )
        if path not in self._inlines:
            self._inlines[path] = _parse_file(path, tuple(self.stack))[0]
        self.stack.append(path)
        self.walk(self._inlines[path], matrix, name)
        self.stack.pop()


def parse_vrml(text: str, base_dir: Path | None = None) -> list[MeshPart]:
    """Meshes of a VRML97 text.

    Parameters
    ----------
    text : str
        File contents, starting with ``#VRML V2.0 utf8``.
    base_dir : Path, optional
        Folder that relative Inline/EXTERNPROTO urls start from (default: working directory).

    Returns
    -------
    list of MeshPart
        One part per rendered Shape with triangles: vertices (n, 3) float64 in world metres
        (all transforms applied), faces (m, 3) int64 counter-clockwise, reflectivity the mean
        Material diffuseColor, name the nearest DEF name (Shape, geometry, ancestor) else
        ``vrml_<k>``.

    Raises
    ------
    SonarRasterError
        On malformed text (message ``<string>:line: ...``), a missing Inline file, an
        unresolvable EXTERNPROTO or an out-of-range coordIndex.
    """
    parser = _Parser(_Source("<string>", text), base_dir, ())
    roots = parser.parse()
    parser.src.warn()
    return _Walker("vrml", ()).walk(roots, np.eye(4), None)


def load_vrml(path: str | Path) -> list[MeshPart]:
    """Meshes of a VRML97 file (``.wrl``, optionally gzipped).

    Parameters
    ----------
    path : str or Path
        The file; Inline and EXTERNPROTO urls are resolved relative to its folder.

    Returns
    -------
    list of MeshPart
        As :func:`parse_vrml`; unnamed parts are called ``<file stem>_<k>``.

    Raises
    ------
    SonarRasterError
        If the file is missing or malformed (message ``<file name>:line: ...``).
    """
    path = Path(path).resolve()
    roots, _ = _parse_file(path, ())
    return _Walker(path.stem, (path,)).walk(roots, np.eye(4), None)
