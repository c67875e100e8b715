"""The machinery every table of the timeline shares: a frozen dataclass of NumPy columns of equal length, each
column declared with its dtype and trailing shape, checked and coerced on construction, and converted losslessly to
and from Arrow (built from the columns' buffers)."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from framechain.arrays import IntArray
from framechain.timeline.errors import TimelineError

__all__ = ["Column", "ColumnTable", "arrow_array", "numpy_of"]


@dataclass(frozen=True)
class Column:
    dtype: str  # "f8", "i8", "bool", "str"
    shape: tuple[int, ...] = ()


@dataclass(frozen=True)
class ColumnTable:
    """Common machinery: column checks, length, masking, concatenation, Arrow round trip."""

    COLUMNS: ClassVar[dict[str, Column]] = {}

    def __post_init__(self) -> None:
        n: int | None = None
        for name, spec in self.COLUMNS.items():
            value = getattr(self, name)
            arr = _coerce(value, spec)
            if arr.shape[1:] != spec.shape:
                raise TimelineError(
                    f"{type(self).__name__}.{name}: expected trailing shape {spec.shape}, got {arr.shape[1:]}"
                )
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise TimelineError(
                    f"{type(self).__name__}: column {name} has {arr.shape[0]} rows, expected {n}"
                )
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        first = next(iter(self.COLUMNS))
        return int(getattr(self, first).shape[0])

    @classmethod
    def empty(cls) -> Self:
        """A table with no rows."""
        return cls(**{name: _empty(spec) for name, spec in cls.COLUMNS.items()})

    def take(self, index: npt.ArrayLike) -> Self:
        """Rows selected by a boolean mask or an index array, as a new table."""
        idx = np.asarray(index)
        return dataclasses.replace(self, **{name: getattr(self, name)[idx] for name in self.COLUMNS})

    @classmethod
    def concat(cls, tables: Iterable[Self]) -> Self:
        """Rows of several tables of this kind, in order."""
        parts = list(tables)
        if not parts:
            return cls.empty()
        return cls(**{name: np.concatenate([getattr(t, name) for t in parts]) for name in cls.COLUMNS})

    def to_arrow(self) -> pa.Table:
        """Lossless Arrow table: vector columns become fixed-size lists."""
        arrays: dict[str, pa.Array] = {}
        for name, spec in self.COLUMNS.items():
            arr = getattr(self, name)
            if spec.shape:
                width = int(np.prod(spec.shape))
                arrays[name] = pa.FixedSizeListArray.from_arrays(arrow_array(arr.reshape(-1)), width)
            else:
                arrays[name] = arrow_array(arr)
        return pa.Table.from_arrays(list(arrays.values()), names=list(arrays))

    @classmethod
    def from_arrow(cls, table: pa.Table) -> Self:
        """Inverse of :meth:`to_arrow`."""
        missing = [name for name in cls.COLUMNS if name not in table.column_names]
        if missing:
            raise TimelineError(f"{cls.__name__}: Arrow table lacks columns {missing}")
        values: dict[str, Any] = {}
        for name, spec in cls.COLUMNS.items():
            col = table.column(name).combine_chunks()
            if spec.shape:
                values[name] = numpy_of(col.flatten()).reshape((len(table), *spec.shape))
            elif spec.dtype == "str":
                values[name] = np.asarray(col.to_pylist(), dtype=str)
            else:
                values[name] = numpy_of(col)
        return cls(**values)

    def equals(self, other: object) -> bool:
        """Exact equality of every column (NaN equal to NaN)."""
        if type(other) is not type(self):
            return False
        for name, spec in self.COLUMNS.items():
            a, b = getattr(self, name), getattr(other, name)
            if a.shape != b.shape:
                return False
            if spec.dtype == "f8":
                if not np.array_equal(a, b, equal_nan=True):
                    return False
            elif not np.array_equal(a, b):
                return False
        return True


def arrow_array(values: npt.NDArray[Any]) -> pa.Array:
    """A one-dimensional float64, int64, bool or unicode NumPy column as an Arrow array, built from its
    buffers: ``pa.array`` would first import pandas (about 0.4 s) to ask whether it was given a Series."""
    n = values.shape[0]
    kind = _ARROW_TYPES.get(values.dtype.str.lstrip("<=|")) or ("str" if values.dtype.kind == "U" else None)
    if kind is None:
        raise TimelineError(f"no Arrow column for NumPy dtype {values.dtype}")
    if kind == "bool":
        return pa.Array.from_buffers(pa.bool_(), n, [None, pa.py_buffer(np.packbits(values, bitorder="little"))])
    if kind != "str":
        return pa.Array.from_buffers(_arrow_type(kind), n, [None, pa.py_buffer(np.ascontiguousarray(values))])
    data, lengths = _utf8(values)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    if offsets[-1] > np.iinfo(np.int32).max:
        raise TimelineError(f"a string column of {offsets[-1]} bytes is beyond an Arrow string array")
    return pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(data)])


def numpy_of(values: pa.Array | pa.ChunkedArray) -> npt.NDArray[Any]:
    """An Arrow column as NumPy, the inverse of :func:`arrow_array`: numbers and booleans read from their buffers
    (nulls as NaN, the column then float64), any other type through ``to_pylist``. ``to_numpy`` would first import
    pandas (0.15 s of a command, and its teardown at exit), whatever the column holds."""
    chunks = values.chunks if isinstance(values, pa.ChunkedArray) else [values]
    parts = [_numpy_chunk(chunk) for chunk in chunks]
    if not parts:
        return np.zeros(0, dtype=_NUMPY_OF_ARROW.get(str(values.type), "float64"))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


#: Arrow types read from their buffers by :func:`numpy_of`, and their NumPy dtypes.
_NUMPY_OF_ARROW = {**{f"{sign}int{bits}": f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64)},
                   "halffloat": "float16", "float": "float32", "double": "float64", "bool": "bool"}


def _numpy_chunk(chunk: pa.Array) -> npt.NDArray[Any]:
    dtype = _NUMPY_OF_ARROW.get(str(chunk.type))
    if dtype is None:
        return np.asarray(chunk.to_pylist())
    n, offset = len(chunk), chunk.offset
    validity, data = chunk.buffers()[:2]
    if dtype == "bool":
        out: npt.NDArray[Any] = _bits(data, offset, n)
    else:
        out = np.frombuffer(data, dtype=dtype, count=offset + n)[offset:] if n else np.zeros(0, dtype=dtype)
    if chunk.null_count:
        out = out.astype(np.float64)
        out[~_bits(validity, offset, n)] = np.nan
    return out


def _bits(buffer: pa.Buffer, offset: int, n: int) -> npt.NDArray[np.bool_]:
    """``n`` bits of an Arrow bitmap from bit ``offset`` (least significant bit first)."""
    packed = np.frombuffer(buffer, dtype=np.uint8)
    return np.unpackbits(packed, bitorder="little", count=offset + n)[offset:].astype(bool)


def _utf8(values: npt.NDArray[np.str_]) -> tuple[bytes, IntArray]:
    """The strings of a unicode column as UTF-8, end to end, and each one's length in bytes; a string
    ends at its first NUL, as ``pa.array`` reads NumPy's NUL-padded unicode."""
    n, width = values.shape[0], values.dtype.itemsize // 4
    codes = np.ascontiguousarray(values).view(np.uint32).reshape(n, width)
    if codes.size and int(codes.max()) >= 0x80:  # beyond ASCII: encode string by string
        encoded = [text.split("\x00", 1)[0].encode() for text in values.tolist()]
        return b"".join(encoded), np.fromiter(map(len, encoded), dtype=np.int64, count=n)
    # ASCII: one byte per code point
    nul = codes == 0
    lengths = np.where(nul.any(axis=1), np.argmax(nul, axis=1), width).astype(np.int64)
    return codes[np.arange(width) < lengths[:, None]].astype(np.uint8).tobytes(), lengths


#: NumPy dtypes (without byte order) of the column kinds :func:`arrow_array` builds.
_ARROW_TYPES = {"f8": "f8", "i8": "i8", "b1": "bool"}


def _arrow_type(dtype: str) -> pa.DataType:
    return {"f8": pa.float64(), "i8": pa.int64(), "bool": pa.bool_(), "str": pa.string()}[dtype]


def _coerce(value: Any, spec: Column) -> npt.NDArray[Any]:
    if spec.dtype == "str":
        arr = np.asarray(value, dtype=str)
        if arr.ndim == 0:
            raise TimelineError("a string column must be one-dimensional")
        return arr
    np_dtype = {"f8": np.float64, "i8": np.int64, "bool": np.bool_}[spec.dtype]
    arr = np.asarray(value)
    if spec.dtype == "i8" and arr.size and arr.dtype.kind == "f":
        raise TimelineError("times and indices are integer nanoseconds/ids, not floats")
    arr = arr.astype(np_dtype, copy=False)
    if arr.ndim == 0:
        raise TimelineError("a column must have one row per sample")
    if arr.shape[0] == 0 and arr.ndim == 1 and spec.shape:
        arr = arr.reshape((0, *spec.shape))
    return arr


def _empty(spec: Column) -> npt.NDArray[Any]:
    np_dtype: Any = {"f8": np.float64, "i8": np.int64, "bool": np.bool_, "str": str}[spec.dtype]
    return np.zeros((0, *spec.shape), dtype=np_dtype)
