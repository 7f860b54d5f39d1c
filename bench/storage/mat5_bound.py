"""A MAT v5 file's compressed variables, checked before scipy inflates them.

In a v5 file (MATLAB 7 ``-v7``) each variable may be one ``miCOMPRESSED`` element: a zlib stream holding an
``miMATRIX`` element (array flags, dimensions, name, real and imaginary data). scipy reads the data sub-element at
the byte count its tag declares, whatever the dimensions say: a 3.9 MB file whose stream inflates to gigabytes
behind a 10-element header drove ``import mat`` to 2.27 GB. Here each variable an import will read is inflated
first in bounded steps, never held whole, and refused as soon as it inflates past what its declared dimensions
allow (the largest MATLAB element is 8 bytes; real and imaginary parts; headers).

Format: MATLAB "MAT-File Format" (The MathWorks), sections "Data Element Format" and "miMATRIX Format".
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Iterator
from typing import BinaryIO, NamedTuple

MI_MATRIX, MI_COMPRESSED = 14, 15
#: numeric classes (mxDOUBLE_CLASS .. mxUINT64_CLASS) and sparse: the only ones an import reads
NUMERIC_CLASSES = range(6, 16)
SPARSE_CLASS = 5
#: inflated bytes read before the header must have been parsed (flags, dims and name take < 200 bytes for any
#: matrix of up to 32 dimensions with a 63-character name)
HEAD_BYTES = 4096
_STEP = 1 << 16


class MatBoundError(ValueError):
    """A compressed variable that inflates beyond its declared size, or a header that cannot be parsed."""


def _pad8(n: int) -> int:
    return (n + 7) // 8 * 8


class Header(NamedTuple):
    mclass: int
    complex_: bool
    logical: bool
    nzmax: int
    dims: tuple[int, ...]
    name: str


#: scipy's class names (scipy.io.matlab whosmat), by mxCLASS
CLASS_NAMES = {1: "cell", 2: "struct", 3: "object", 4: "char", 5: "sparse", 6: "double", 7: "single", 8: "int8",
               9: "uint8", 10: "int16", 11: "uint16", 12: "int32", 13: "uint32", 14: "int64", 15: "uint64",
               16: "function_handle", 17: "opaque"}


def _elements(head: bytes, order: str) -> Header:
    """The header of a matrix from the start of its miMATRIX element (tag included)."""
    def tag(at: int) -> tuple[int, int, int, int]:  # (type, nbytes, offset of the data, offset of the next)
        if at + 8 > len(head):
            raise MatBoundError("a variable's header is cut short or beyond its first 4 KiB")
        word, nbytes = struct.unpack_from(order + "II", head, at)
        if word >> 16:  # small data element: type and size in one word, data in the next 4 bytes
            return word & 0xFFFF, word >> 16, at + 4, at + 8
        return word, nbytes, at + 8, at + 8 + _pad8(nbytes)

    mdtype, _, at, _ = tag(0)
    if mdtype != MI_MATRIX:
        raise MatBoundError(f"an element of type {mdtype} where a matrix was expected")
    _, _, at_flags, at = tag(at)
    if at_flags + 8 > len(head):
        raise MatBoundError("a variable's header is cut short")
    flags, nzmax = struct.unpack_from(order + "II", head, at_flags)
    _, n, at_dims, at = tag(at)
    if n % 4 or at_dims + n > len(head):
        raise MatBoundError("bad dimensions sub-element")
    dims = struct.unpack_from(f"{order}{n // 4}i", head, at_dims)
    _, n, at_name, _ = tag(at)
    name = head[at_name:at_name + n].decode("latin1")
    if any(d < 0 for d in dims):
        raise MatBoundError(f"variable {name!r}: negative dimension in {dims}")
    return Header(flags & 0xFF, bool(flags & 0x0800), bool(flags & 0x0200), nzmax, tuple(dims), name)


def _allowed(h: Header) -> int:
    """Most inflated bytes a matrix of this header can take."""
    header = 8 + 16 + 8 + _pad8(4 * len(h.dims)) + 8 + _pad8(len(h.name))
    parts = 2 if h.complex_ else 1
    if h.mclass in NUMERIC_CLASSES:
        return header + parts * (8 + _pad8(8 * math.prod(h.dims)))
    if h.mclass == SPARSE_CLASS:
        cols = h.dims[1] if len(h.dims) > 1 else 1
        return header + 8 + _pad8(4 * h.nzmax) + 8 + _pad8(4 * (cols + 1)) + parts * (8 + _pad8(8 * h.nzmax))
    raise MatBoundError(f"variable {h.name!r} is not a numeric matrix ({CLASS_NAMES.get(h.mclass, h.mclass)})")


def list_variables(path: str) -> list[tuple[str, tuple[int, ...], str]]:
    """(name, dimensions, class) of each variable of a v5 file, as scipy's ``whosmat`` gives them, from the
    headers alone: a compressed variable is inflated only as far as its header (whosmat inflated it whole)."""
    return [(h.name, h.dims, "logical" if h.logical else CLASS_NAMES.get(h.mclass, "unknown"))
            for h in walk(path, set())]


def check_inflation(path: str, names: set[str]) -> None:
    """Inflate every compressed variable of ``names`` in a v5 file in bounded steps; :class:`MatBoundError` (one
    line) for one that inflates beyond its declared dimensions. Other variables are skipped unread."""
    for _ in walk(path, names):
        pass


def walk(path: str, names: set[str]) -> Iterator[Header]:
    """Each variable's header; the compressed ones of ``names`` are inflated whole, in bounded steps, and checked
    against their declared size."""
    with open(path, "rb") as fh:
        header = fh.read(128)
        if len(header) < 128:
            raise MatBoundError("shorter than a MAT file's 128-byte header")
        order = "<" if header[126:128] == b"IM" else ">"
        while True:
            raw = fh.read(8)
            if len(raw) < 8:
                return
            mdtype, nbytes = struct.unpack(order + "II", raw)
            end = fh.tell() + nbytes
            if mdtype == MI_COMPRESSED:
                yield _inflated(fh, nbytes, order, names)
            elif mdtype == MI_MATRIX:
                yield _elements(raw + fh.read(min(nbytes, HEAD_BYTES)), order)
            else:
                raise MatBoundError(f"an element of type {mdtype} where a variable was expected")
            fh.seek(end)


def _inflated(fh: BinaryIO, nbytes: int, order: str, names: set[str]) -> Header:
    """The header of one compressed variable; inflated whole (bounded) when it is one of ``names``."""
    inflate = zlib.decompressobj()
    head, total, left, pending = b"", 0, nbytes, b""
    found: Header | None = None
    limit = HEAD_BYTES
    while True:
        if not pending:
            pending = fh.read(min(_STEP, left)) if left else b""
            if left and not pending:  # the file ends inside the variable: nothing more will come
                raise MatBoundError(f"the file ends {left} bytes short of a compressed variable's end (truncated)")
            left -= len(pending)
        try:
            out = inflate.decompress(pending, max(1, min(limit + 1 - total, _STEP)))
        except zlib.error as exc:
            raise MatBoundError(f"a compressed variable is not a valid zlib stream ({exc})") from None
        pending = inflate.unconsumed_tail
        total += len(out)
        if found is None:
            head += out
            if len(head) >= HEAD_BYTES or inflate.eof or not (pending or left):
                found = _elements(head, order)
                if found.name not in names:
                    return found
                limit, head = _allowed(found), b""
        if total > limit:
            raise MatBoundError(f"variable {found.name!r} declares {'x'.join(map(str, found.dims))} elements "
                                f"({limit} bytes at most) but inflates beyond that; a damaged or hostile file")
        if inflate.eof or not (pending or left):
            return found
