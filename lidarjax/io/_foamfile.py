"""Low-level OpenFOAM file parsing: FoamFile headers, ASCII and binary lists, dictionaries.

Private to `lidarjax.io`. Everything is plain numpy: the large lists (points, faces, owner,
neighbour, `internalField`) are read in one vectorised step each (`numpy.frombuffer` for
binary, `numpy.fromstring` for ASCII), never token by token, so a 5e6-cell mesh reads in
seconds. Compressed files (`name.gz`) are read transparently.

Format notes (OpenFOAM v1.x to v2x12 and the Foundation's versions alike):

- a header dictionary `FoamFile { format ascii|binary; class ...; arch "LSB;label=32;
  scalar=64"; }` (the `arch` entry gives the byte widths of labels and scalars in binary
  files; defaults 32-bit labels and 64-bit scalars);
- a list is `N ( item item ... )` (ASCII), `N{item}` (ASCII, all items equal), or in binary
  `N (` followed by the raw little-endian bytes of the items and `)`;
- faces are a `faceList` (`N ( k(a b c ...) ... )`) or a `faceCompactList` (two lists:
  `N+1` offsets, then the flat point labels), in either format.
"""

from __future__ import annotations

import dataclasses
import gzip
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from .._util import file_error

__all__: list[str] = []

_WS = frozenset(b" \t\r\n\f\v")
_PUNCT = frozenset(b"(){};[]")
_PAREN_TABLE = bytes.maketrans(b"()", b"  ")
_NUMBER_RE = re.compile(rb"[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?)$")
_CLOSE_CLOSE_RE = re.compile(rb"\)\s*\)")
_COMPONENTS = {"scalar": 1, "label": 1, "vector": 3, "symmTensor": 6, "tensor": 9,
               "sphericalTensor": 1}


def resolve_file(path: Path) -> Path | None:
    """`path` or `path.gz`, whichever exists (plain first), else None."""
    if path.is_file():
        return path
    gz = path.with_name(path.name + ".gz")
    return gz if gz.is_file() else None


def read_bytes(path: Path) -> bytes:
    """The file's bytes, gunzipped when the name ends in `.gz`."""
    if path.suffix == ".gz":
        try:
            with gzip.open(path, "rb") as fh:
                return fh.read()
        except (OSError, EOFError) as err:
            raise file_error(path, None, f"not a readable gzip file ({err})") from None
    return path.read_bytes()


@dataclasses.dataclass(frozen=True)
class Header:
    """The `FoamFile` header: format, class, object and the binary widths."""

    binary: bool
    cls: str
    obj: str
    label_dtype: np.dtype
    scalar_dtype: np.dtype
    note: str


class Cursor:
    """A position in an OpenFOAM file with a small tokenizer (text parts only)."""

    def __init__(self, data: bytes, path: Path):
        self.data = data
        self.path = path
        self.pos = 0
        self.header: Header | None = None

    # -- errors --------------------------------------------------------------------
    def line(self, pos: int | None = None) -> int:
        return self.data.count(b"\n", 0, self.pos if pos is None else pos) + 1

    def error(self, message: str, pos: int | None = None) -> ValueError:
        return file_error(self.path, self.line(pos), message)

    # -- tokens --------------------------------------------------------------------
    def skip_space(self) -> None:
        data, n, i = self.data, len(self.data), self.pos
        while i < n:
            c = data[i]
            if c in _WS:
                i += 1
            elif c == 0x2F and i + 1 < n and data[i + 1] == 0x2F:  # // comment
                j = data.find(b"\n", i)
                i = n if j < 0 else j + 1
            elif c == 0x2F and i + 1 < n and data[i + 1] == 0x2A:  # /* comment */
                j = data.find(b"*/", i + 2)
                if j < 0:
                    raise self.error("unterminated /* comment", i)
                i = j + 2
            else:
                break
        self.pos = i

    def at_end(self) -> bool:
        self.skip_space()
        return self.pos >= len(self.data)

    def peek(self) -> bytes:
        self.skip_space()
        if self.pos >= len(self.data):
            return b""
        c = self.data[self.pos]
        if c in _PUNCT:
            return bytes([c])
        return self._word(advance=False)

    def _word(self, advance: bool) -> bytes:
        data, n, i = self.data, len(self.data), self.pos
        if data[i] == 0x22:  # quoted string
            j = data.find(b'"', i + 1)
            if j < 0:
                raise self.error("unterminated string")
            if advance:
                self.pos = j + 1
            return data[i: j + 1]
        j = i
        depth = 0
        while j < n:
            c = data[j]
            if c == 0x3C:  # List<vector>: keep the angle brackets in the word
                depth += 1
            elif c == 0x3E:
                depth -= 1
            elif depth <= 0 and (c in _WS or c in _PUNCT):
                break
            j += 1
        if advance:
            self.pos = j
        return data[i:j]

    def token(self) -> bytes:
        self.skip_space()
        if self.pos >= len(self.data):
            raise self.error("unexpected end of file")
        c = self.data[self.pos]
        if c in _PUNCT:
            self.pos += 1
            return bytes([c])
        return self._word(advance=True)

    def expect(self, tok: bytes, what: str) -> None:
        start = self.pos
        got = self.token()
        if got != tok:
            raise self.error(f"expected {tok.decode()!r} {what}, found {got[:40].decode(errors='replace')!r}",
                             start)

    # -- header --------------------------------------------------------------------
    def read_header(self) -> Header:
        self.skip_space()
        if self.peek() != b"FoamFile":
            raise self.error("no FoamFile header; is this an OpenFOAM file?")
        self.token()
        entries = self.read_dict()
        fmt = str(entries.get("format", "ascii")).strip('"')
        if fmt not in ("ascii", "binary"):
            raise self.error(f"FoamFile format must be ascii or binary, found {fmt!r}")
        arch = str(entries.get("arch", "")).strip('"')
        label_bits, scalar_bits = 32, 64
        for part in arch.split(";"):
            key, _, val = part.partition("=")
            if key.strip() == "label" and val.strip():
                label_bits = int(val)
            elif key.strip() == "scalar" and val.strip():
                scalar_bits = int(val)
        if label_bits not in (32, 64) or scalar_bits not in (32, 64):
            raise self.error(f"unsupported arch {arch!r}: labels and scalars must be 32 or 64 bits")
        endian = ">" if arch.startswith("MSB") else "<"
        header = Header(
            binary=fmt == "binary",
            cls=str(entries.get("class", "")).strip('"'),
            obj=str(entries.get("object", "")).strip('"'),
            label_dtype=np.dtype(f"{endian}i{label_bits // 8}"),
            scalar_dtype=np.dtype(f"{endian}f{scalar_bits // 8}"),
            note=str(entries.get("note", "")).strip('"'),
        )
        self.header = header
        return header

    # -- dictionaries --------------------------------------------------------------
    def read_dict(self) -> dict[str, Any]:
        """Read `{ key value; key { ... } ... }` (the opening brace is next)."""
        self.expect(b"{", "to open a dictionary")
        out: dict[str, Any] = {}
        while True:
            tok = self.token()
            if tok == b"}":
                return out
            if tok in (b";",):
                continue
            if tok in (b"(", b")", b"{", b"["):
                raise self.error(f"unexpected {tok.decode()!r} where a keyword was expected")
            key = tok.decode(errors="replace").strip('"')
            if self.peek() == b"{":
                out[key] = self.read_dict()
            else:
                out[key] = self.read_value()
        return out

    def read_value(self) -> Any:
        """Read an entry's value up to its `;`: a list of tokens, with `uniform`/`nonuniform`
        fields turned into numpy arrays (key `('uniform', array)` / `('nonuniform', array)`)."""
        parts: list[Any] = []
        while True:
            nxt = self.peek()
            if nxt == b"":
                raise self.error("unexpected end of file inside an entry (missing ';')")
            if nxt == b";":
                self.token()
                break
            if nxt == b"}":
                raise self.error("missing ';' before '}'")
            if nxt == b"uniform":
                self.token()
                parts.append(("uniform", self.read_item()))
            elif nxt == b"nonuniform":
                self.token()
                parts.append(("nonuniform", self.read_typed_list()))
            elif nxt in (b"(", b"["):
                parts.append(self.read_item())
            elif nxt == b"{":
                parts.append(self.read_dict())
            else:
                parts.append(self.token().decode(errors="replace"))
        if len(parts) == 1:
            return parts[0]
        return parts

    def read_item(self) -> Any:
        """A number, a word, or a parenthesised/bracketed group of numbers (as an array)."""
        tok = self.peek()
        if tok in (b"(", b"["):
            close = b")" if tok == b"(" else b"]"
            start = self.pos
            depth = 0
            data = self.data
            i = self.pos
            while i < len(data):
                c = data[i: i + 1]
                if c in (b"(", b"["):
                    depth += 1
                elif c in (b")", b"]"):
                    depth -= 1
                    if depth == 0:
                        break
                i += 1
            if depth != 0:
                raise self.error(f"unbalanced {tok.decode()!r}", start)
            text = data[start + 1: i].translate(_PAREN_TABLE)
            self.pos = i + 1
            del close
            try:
                return _parse_numbers(text, np.float64)
            except ValueError:
                return text.decode(errors="replace").split()
        word = self.token()
        if _NUMBER_RE.match(word):
            return float(word)
        return word.decode(errors="replace")

    # -- lists ---------------------------------------------------------------------
    def read_typed_list(self) -> np.ndarray:
        """`List<type> N (...)` after `nonuniform`: returns `(N,)` or `(N, k)` float64."""
        start = self.pos
        if self.peek().isdigit():  # "nonuniform 0" (an empty field, written without a type)
            n = self.read_size("data")
            if n != 0:
                raise self.error(f"expected List<type> before a non-empty list of {n} items", start)
            self.skip_space()
            if self.data[self.pos: self.pos + 1] == b"(":
                self.pos += 1
                self.expect(b")", "closing an empty list")
            return np.zeros((0,))
        tok = self.token().decode(errors="replace")
        m = re.fullmatch(r"List<(\w+)>", tok)
        if not m or m.group(1) not in _COMPONENTS:
            raise self.error(f"expected List<scalar|vector|...> after 'nonuniform', found {tok!r}", start)
        ncomp = _COMPONENTS[m.group(1)]
        return self.read_list(ncomp, np.float64)

    def read_size(self, what: str) -> int:
        self.skip_space()
        start = self.pos
        data, i = self.data, self.pos
        while i < len(data) and 0x30 <= data[i] <= 0x39:
            i += 1
        if i == start:
            raise self.error(f"expected the size of the {what} list, found "
                             f"{data[start: start + 20].decode(errors='replace')!r}")
        self.pos = i
        return int(data[start:i])

    def read_list(self, ncomp: int, kind: Any, what: str = "data") -> np.ndarray:
        """`N (...)`, `N{...}` or binary `N (bytes)`; returns `(N,)` (ncomp 1) or `(N, ncomp)`.

        `kind` is np.float64 for scalars or np.int64 for labels."""
        n = self.read_size(what)
        self.skip_space()
        start = self.pos
        data = self.data
        opener = data[self.pos: self.pos + 1]
        shape = (n,) if ncomp == 1 else (n, ncomp)
        if opener == b"{":  # uniform list N{value}
            self.pos += 1
            item = self.read_item()
            self.expect(b"}", "closing a uniform list")
            value = np.asarray(item, dtype=np.float64).reshape(-1)
            if value.size != ncomp:
                raise self.error(f"uniform list item has {value.size} components, expected {ncomp}", start)
            return np.broadcast_to(value.astype(kind), (n, ncomp)).reshape(shape).copy()
        if opener != b"(":
            raise self.error(f"expected '(' opening a list of {n} {what} items, found "
                             f"{data[start: start + 20].decode(errors='replace')!r}")
        header = self.header
        if header is not None and header.binary and n > 0:
            dt = header.label_dtype if kind is np.int64 else header.scalar_dtype
            nbytes = n * ncomp * dt.itemsize
            end = start + 1 + nbytes
            if end >= len(data) or data[end: end + 1] != b")":
                raise self.error(
                    f"binary list of {n} {what} items ({nbytes} bytes of {dt.itemsize}-byte values from "
                    "the header's arch) is truncated or does not end with ')'; the file is corrupt or "
                    "its arch entry is wrong", start)
            arr = np.frombuffer(data, dtype=dt, count=n * ncomp, offset=start + 1)
            self.pos = end + 1
            return arr.astype(kind).reshape(shape)
        # ASCII
        if n == 0:
            self.pos += 1
            self.expect(b")", "closing an empty list")
            return np.zeros(shape, dtype=kind)
        if ncomp == 1:
            end = data.find(b")", start + 1)
            close_len = 1
        else:
            m = _CLOSE_CLOSE_RE.search(data, start + 1)
            end = -1 if m is None else m.start() + 1
            close_len = 0 if m is None else m.end() - m.start() - 1
        if end < 0:
            raise self.error(f"list of {n} {what} items is not closed by ')'", start)
        text = data[start + 1: end].translate(_PAREN_TABLE)
        try:
            arr = _parse_numbers(text, kind)
        except ValueError:
            raise self._bad_ascii(start + 1, end, kind, what) from None
        if arr.size != n * ncomp:
            raise self.error(f"list announces {n} {what} items of {ncomp} components but holds "
                             f"{arr.size} numbers ({arr.size / ncomp:g} items)", start)
        self.pos = end + close_len
        return arr.reshape(shape)

    def _bad_ascii(self, start: int, end: int, kind: Any, what: str) -> ValueError:
        """Locate the first unparseable token of an ASCII list for the error message."""
        for m in re.finditer(rb"[^\s()]+", self.data[start:end]):
            tok = m.group()
            try:
                (int if kind is np.int64 else float)(tok)
            except ValueError:
                return self.error(f"{what} list: expected a number, found "
                                  f"{tok[:30].decode(errors='replace')!r}", start + m.start())
        return self.error(f"{what} list: unreadable numbers", start)

    def read_face_list(self) -> tuple[np.ndarray, np.ndarray]:
        """A `faceList` or `faceCompactList`: returns `(offsets (nFaces+1,), labels (M,))`."""
        header = self.header
        compact = header is not None and header.cls == "faceCompactList"
        if compact:
            offsets = self.read_list(1, np.int64, "face offsets")
            labels = self.read_list(1, np.int64, "face point labels")
            if offsets.size < 1 or offsets[0] != 0 or offsets[-1] != labels.size or np.any(
                np.diff(offsets) < 3
            ):
                raise self.error("faceCompactList offsets are inconsistent with the point labels "
                                 "(each face needs >= 3 points)")
            return offsets, labels
        n = self.read_size("faces")
        self.skip_space()
        start = self.pos
        if self.data[start: start + 1] != b"(":
            raise self.error(f"expected '(' opening the list of {n} faces", start)
        if n == 0:
            self.pos += 1
            self.expect(b")", "closing an empty list")
            return np.zeros(1, np.int64), np.zeros(0, np.int64)
        m = _CLOSE_CLOSE_RE.search(self.data, start + 1)
        if m is None:
            raise self.error(f"list of {n} faces is not closed by ')'", start)
        end = m.start() + 1
        block = self.data[start + 1: end]
        try:
            flat = _parse_numbers(block.translate(_PAREN_TABLE), np.int64)
        except ValueError:
            raise self._bad_ascii(start + 1, end, np.int64, "face") from None
        k = int(flat[0]) if flat.size else 0
        if k >= 3 and flat.size == n * (k + 1) and np.all(flat[:: k + 1] == k):
            sizes = np.full(n, k, np.int64)
        else:
            sizes = np.array([int(s) for s in re.findall(rb"(\d+)\s*\(", block)], dtype=np.int64)
        if sizes.size != n or np.any(sizes < 3) or flat.size != n + int(sizes.sum()):
            raise self.error(f"face list announces {n} faces but its entries do not match "
                             "('k(a b c ...)' with k >= 3 labels each)", start)
        offsets = np.zeros(n + 1, np.int64)
        np.cumsum(sizes, out=offsets[1:])
        keep = np.ones(flat.size, bool)
        keep[offsets[:-1] + np.arange(n)] = False
        self.pos = m.end()
        return offsets, flat[keep]


def _parse_numbers(text: bytes, kind: Any) -> np.ndarray:
    """Whitespace-separated numbers to a 1-D array; ValueError when something is not one."""
    if not text.strip():
        return np.zeros(0, dtype=kind)
    return np.fromstring(text.decode("ascii", errors="replace"), dtype=kind, sep=" ")


def open_file(path: Path) -> Cursor:
    """Read `path` (or `path.gz`), parse its header, and return a cursor after it."""
    real = resolve_file(path)
    if real is None:
        raise FileNotFoundError(f"OpenFOAM file not found: {os.fspath(path)} (nor {path.name}.gz)")
    cur = Cursor(read_bytes(real), real)
    cur.read_header()
    return cur
