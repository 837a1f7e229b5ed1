"""Reading the arrays of a scene file (`.s3d`: an uncompressed numpy `.npz`) without trusting it.

`np.load` allocates what a `.npy` header declares and lets the zip and header parsers' own exceptions
through. Here every member's size is checked in the zip directory, its `.npy` header is parsed alone
(`numpy.lib.format.read_magic`, `read_array_header_1_0/2_0`) and its dtype and shape are checked against
the caller's `ArraySpec` before a byte of data is read; every failure is a one-line `UserError` naming the
array and the allowed range."""
from __future__ import annotations

import json
import struct
import tokenize
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from numpy.lib import format as npy

from .errors import UserError

__all__ = ["ArraySpec", "read_arrays", "parse_header", "MAX_HEADER_BYTES", "MAX_MEMBERS"]

MAX_HEADER_BYTES = 1 << 16   # the scene's JSON header
MAX_MEMBERS = 16             # entries of the zip (a scene has three)
_HEADER_ERRORS = (ValueError, SyntaxError, TypeError, KeyError, tokenize.TokenError, RecursionError, MemoryError,
                  EOFError, struct.error, OverflowError)
_ZIP_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, OSError, EOFError, ValueError,
               zlib.error, struct.error, RuntimeError)


@dataclass(frozen=True)
class ArraySpec:
    """What one member array may be: `dtypes` (numpy kind+size codes such as "u1", "f4"; any byte order),
    `ndim` (None: any), `check` (shape -> bool, after ndim) and `allowed` (the range in words, for the error)."""

    dtypes: tuple
    ndim: int | None
    check: Callable[[tuple], bool]
    allowed: str


def _member_header(f, name: str, where: str) -> tuple[tuple, bool, np.dtype]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # numpy warns of headers it had to repair
            version = npy.read_magic(f)
            read = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}.get(version)
            if read is None:
                raise ValueError(f"npy version {version}")
            return read(f)
    except _HEADER_ERRORS as e:
        raise UserError(f"{where}: array {name!r} has a corrupt .npy header ({type(e).__name__})") from None


def _check_spec(name: str, shape: tuple, dtype: np.dtype, spec: ArraySpec, where: str) -> None:
    kind = f"{dtype.kind}{dtype.itemsize}"
    ok = (dtype.fields is None and dtype.subdtype is None and kind in spec.dtypes
          and (spec.ndim is None or len(shape) == spec.ndim) and all(0 <= n for n in shape))
    if not ok or not spec.check(shape):
        raise UserError(f"{where}: array {name!r} is {shape} {dtype.str}; allowed: {spec.allowed}")


def read_arrays(path, specs: dict[str, ArraySpec]) -> dict[str, np.ndarray]:
    """The arrays named in `specs` from the `.npz` at `path` (members `NAME.npy`), each checked against its
    spec from its header before its data is read. Other members are ignored (at most MAX_MEMBERS)."""
    where = str(path)
    out = {}
    try:
        with zipfile.ZipFile(Path(path)) as z:
            infos = z.infolist()
            if len(infos) > MAX_MEMBERS:
                raise UserError(f"{where}: {len(infos)} entries in the zip; a scene file has {len(specs)}")
            members = {i.filename[:-4]: i for i in infos if i.filename.endswith(".npy")}
            for name, spec in specs.items():
                info = members.get(name)
                if info is None:
                    raise UserError(f"{where} is not a snapshot3d scene file (no array {name!r})")
                with z.open(info) as f:
                    shape, fortran, dtype = _member_header(f, name, where)
                    _check_spec(name, shape, dtype, spec, where)
                    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
                    if info.file_size != f.tell() + nbytes:
                        raise UserError(f"{where}: array {name!r} declares {nbytes} bytes of data but the file holds "
                                        f"{info.file_size - f.tell()}")
                    data = f.read(nbytes)
                if len(data) != nbytes:
                    raise UserError(f"{where}: array {name!r} is truncated")
                arr = np.frombuffer(data, dtype).reshape(shape, order="F" if fortran else "C")
                out[name] = np.ascontiguousarray(arr.astype(dtype.newbyteorder("=")))
    except _ZIP_ERRORS as e:
        raise UserError(f"{where} is not a snapshot3d scene file ({type(e).__name__})") from None
    return out


def parse_header(path, data: np.ndarray) -> dict:
    """The scene's JSON header (uint8 bytes of UTF-8) -> dict; UserError when it is not a JSON object."""
    try:
        header = json.loads(data.tobytes().decode("utf-8"))
    except (ValueError, RecursionError) as e:   # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise UserError(f"{path} is not a snapshot3d scene file (header: {type(e).__name__})") from None
    if not isinstance(header, dict):
        raise UserError(f"{path}: the scene header must be a JSON object, got {type(header).__name__}")
    return header
