"""Compare two viscx files level by level (the library behind ``viscx diff``).

The walk is generic: every group, dataset and attribute of both files is
visited, so new levels (``V0``, ``V1``, ...) are compared without changes here.
What is compared, in this order for each object:

- attributes (strings holding JSON, such as ``options`` and ``levels``, are
  parsed and compared key by key);
- presence and kind (group or dataset);
- dataset shape and dtype *kind* (float, integer, bool, string, ...; an int32
  holding the same values as an int64 is equal);
- values: integers, bools and strings exactly, floats and complex numbers with
  :func:`numpy.isclose` semantics, ``|a - b| <= atol + rtol * |b|`` with B as
  the reference (NaN equals NaN in the same place).

Ignored: ``/provenance`` (timings differ on every build) and the root attribute
``viscx_version`` (who wrote the file, not what it holds).
"""

import json
import math
from dataclasses import dataclass, field

import h5py
import numpy as np

from viscx.tolerances import DEFAULT_ATOL, DEFAULT_RTOL

__all__ = ["Difference", "DiffResult", "diff_files", "diff_groups", "DEFAULT_RTOL", "DEFAULT_ATOL", "IGNORED"]

#: Paths left out of the comparison; ``@`` names an attribute of the object before it.
IGNORED = ("/provenance", "/@viscx_version")

# datasets are read in slabs of about this many elements so that large levels
# are compared without holding both copies in memory
_BLOCK = 1 << 22


@dataclass(frozen=True)
class Difference:
    """One place where two files differ.

    Attributes
    ----------
    path : str
        HDF5 path of the object, ``@name`` appended for an attribute
        (``/scene/vertices``, ``/@options``).
    kind : str
        ``"missing"`` (absent from one file; the absent side is None),
        ``"type"`` (group in one file, dataset in the other), ``"shape"``,
        ``"dtype"`` (kinds differ) or ``"value"``.
    index : tuple or None
        For ``"value"``: the first differing index (array position, or the key
        path inside a JSON attribute).
    a, b
        The two sides: the values at ``index``, the shapes, dtype kinds or
        object kinds.
    count : int
        Number of differing elements (1 unless ``kind == "value"`` on an array).
    size : int
        Number of elements compared.
    """

    path: str
    kind: str
    index: tuple = None
    a: object = None
    b: object = None
    count: int = 1
    size: int = 1

    def describe(self, name_a="A", name_b="B"):
        """One line for a person, e.g. ``/scene/vertices[3, 1]: 0.5 != 0.75 (1 of 72 values differ)``."""
        where = self.path + ("" if not self.index else "[" + ", ".join(map(repr, self.index)) + "]")
        if self.kind == "missing":
            return f"{where}: {self.a if self.b is None else self.b} only in {name_a if self.b is None else name_b}"
        if self.kind == "value":
            tail = f" ({self.count} of {self.size} values differ)" if self.size > 1 else ""
            return f"{where}: {self.a!r} != {self.b!r}{tail}"
        return f"{where}: {self.kind} {self.a} != {self.b}"


@dataclass
class DiffResult:
    """The outcome of :func:`diff_files`.

    Attributes
    ----------
    differences : list of Difference
        The first ``max_items`` differences, in file order.
    total : int
        How many differences there are in all.
    """

    path_a: str
    path_b: str
    rtol: float
    atol: float
    differences: list = field(default_factory=list)
    total: int = 0

    @property
    def equal(self):
        return self.total == 0

    def report(self):
        """The human report: a list of lines (a single line when the files are equal)."""
        tolerances = f"rtol {self.rtol:g}, atol {self.atol:g}"
        if self.equal:
            return [f"{self.path_a} and {self.path_b} are equal ({tolerances})"]
        lines = [f"{self.path_a} and {self.path_b} differ in {self.total} place(s) ({tolerances}):"]
        lines += ["  " + d.describe(self.path_a, self.path_b) for d in self.differences]
        if self.total > len(self.differences):
            lines.append(f"  ... and {self.total - len(self.differences)} more (--max-report to see them)")
        return lines


class _Collector:
    """Keeps the first ``limit`` differences and counts them all."""

    def __init__(self, limit):
        self.limit, self.items, self.total = limit, [], 0

    def add(self, difference):
        self.total += 1
        if len(self.items) < self.limit:
            self.items.append(difference)


def diff_files(path_a, path_b, rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL, max_items=10, ignore=IGNORED):
    """Compare two viscx files (see module docstring for what is compared).

    Parameters
    ----------
    path_a, path_b : str or Path
        B is the reference for the relative tolerance.
    rtol, atol : float
        Float tolerances, :func:`numpy.isclose` semantics; 0 and 0 compare exactly.
    max_items : int
        How many differences to keep (all are counted).
    ignore : sequence of str
        Paths to leave out (``/group`` or ``/group@attribute``).

    Returns
    -------
    DiffResult

    Raises
    ------
    ViscxError
        When either file is missing, not HDF5, not a viscx file or of a newer format.
    """
    from viscx.formats.hdf5 import ViscxFile

    with ViscxFile(path_a) as fa, ViscxFile(path_b) as fb:
        found = _Collector(max_items)
        diff_groups(fa.h5, fb.h5, found.add, rtol=rtol, atol=atol, ignore=ignore)
    return DiffResult(str(path_a), str(path_b), rtol, atol, found.items, found.total)


def diff_groups(group_a, group_b, report, rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL, ignore=IGNORED):
    """Compare two h5py groups recursively, calling ``report(Difference)`` for each difference."""
    ignore = set(ignore)
    _diff_attrs(group_a, group_b, report, rtol, atol, ignore)
    names = list(group_a) + [name for name in group_b if name not in group_a]
    for name in names:
        path = f"{group_a.name.rstrip('/')}/{name}"
        if path in ignore:
            continue
        a, b = group_a.get(name), group_b.get(name)
        kind_a, kind_b = _object_kind(a), _object_kind(b)
        if kind_a is None or kind_b is None:
            report(Difference(path, "missing", a=kind_a, b=kind_b))
        elif kind_a != kind_b:
            report(Difference(path, "type", a=kind_a, b=kind_b))
        elif kind_a == "group":
            diff_groups(a, b, report, rtol, atol, ignore)
        elif kind_a == "dataset":
            _diff_attrs(a, b, report, rtol, atol, ignore)
            _diff_dataset(a, b, path, report, rtol, atol)


def _object_kind(obj):
    if obj is None:
        return None
    if isinstance(obj, h5py.Group):
        return "group"
    if isinstance(obj, h5py.Dataset):
        return "dataset"
    return type(obj).__name__


def _dtype_kind(dtype):
    """The kind of values a dtype holds: float, complex, integer, bool, string or other."""
    if h5py.check_string_dtype(dtype) is not None or dtype.kind in "SU":
        return "string"
    return {"f": "float", "c": "complex", "i": "integer", "u": "integer", "b": "bool"}.get(dtype.kind, "other")


def _mismatch(a, b, kind, rtol, atol):
    """Flat positions where two same-shape arrays differ, as an (k,) int array."""
    a, b = np.asarray(a).reshape(-1), np.asarray(b).reshape(-1)
    if kind in ("float", "complex"):
        same = np.isclose(a, b, rtol=rtol, atol=atol, equal_nan=True)
    else:
        same = np.asarray(a == b, dtype=bool).reshape(-1)
    return np.flatnonzero(~same)


def _scalar(value):
    """A numpy element as a plain Python value for the report."""
    value = value.item() if isinstance(value, np.generic) else value
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else value


def _diff_dataset(a, b, path, report, rtol, atol):
    if a.shape != b.shape:
        report(Difference(path, "shape", a=a.shape, b=b.shape))
        return
    kind_a, kind_b = _dtype_kind(a.dtype), _dtype_kind(b.dtype)
    if kind_a != kind_b:
        report(Difference(path, "dtype", a=kind_a, b=kind_b))
        return
    shape = a.shape
    if kind_a == "string":  # compare text, whatever the storage (fixed or variable length)
        a, b = a.asstr(), b.asstr()
    count, first = 0, None
    for rows in _slabs(shape):
        xa, xb = np.asarray(a[rows]), np.asarray(b[rows])
        bad = _mismatch(xa, xb, kind_a, rtol, atol)
        if len(bad) and first is None:
            local = np.unravel_index(bad[0], xa.shape)
            first = (local[0] + rows.start, *local[1:]) if shape else ()
            first = tuple(int(i) for i in first)
            values = (_scalar(xa[local]), _scalar(xb[local]))
        count += len(bad)
    if count:
        report(Difference(path, "value", first, *values, count=count, size=math.prod(shape)))


def _slabs(shape):
    """Index expressions covering a dataset of ``shape`` in slabs of rows of about ``_BLOCK`` elements."""
    if not shape:
        yield ()
        return
    step = max(1, _BLOCK // max(1, math.prod(shape[1:])))
    for start in range(0, max(shape[0], 1), step):
        yield slice(start, min(start + step, shape[0]))


def _attr_value(value):
    """An attribute as a comparable Python/numpy value: text decoded, JSON text parsed."""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, str) and value[:1] in ("{", "["):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def _diff_attrs(obj_a, obj_b, report, rtol, atol, ignore):
    base = obj_a.name if obj_a.name == "/" else obj_a.name + "/"
    names = list(obj_a.attrs) + [name for name in obj_b.attrs if name not in obj_a.attrs]
    for name in names:
        path = f"{base}@{name}"
        if path in ignore:
            continue
        in_a, in_b = name in obj_a.attrs, name in obj_b.attrs
        if not (in_a and in_b):
            report(Difference(path, "missing", a="attribute" if in_a else None, b="attribute" if in_b else None))
            continue
        _diff_values(_attr_value(obj_a.attrs[name]), _attr_value(obj_b.attrs[name]), path, (), report, rtol, atol)


def _value_kind(value):
    if isinstance(value, (bool, np.bool_)):
        return "bool"
    if isinstance(value, (int, np.integer)):
        return "integer"
    if isinstance(value, (float, np.floating)):
        return "float"
    if isinstance(value, (str, dict, list, type(None))):
        return type(value).__name__
    return "array"


def _diff_values(a, b, path, keys, report, rtol, atol):
    """Compare two attribute values (JSON structures, scalars or arrays); ``keys`` is the JSON key path so far."""
    kind_a, kind_b = _value_kind(a), _value_kind(b)
    if {kind_a, kind_b} == {"integer", "float"}:  # 1 and 1.0 in JSON are the same number
        kind_a = kind_b = "float"
    if kind_a != kind_b:
        report(Difference(path, "dtype", keys or None, kind_a, kind_b))
    elif kind_a == "dict":
        for key in list(a) + [k for k in b if k not in a]:
            if key not in a or key not in b:
                in_a, in_b = key in a, key in b
                report(Difference(path, "missing", (*keys, key), "key" if in_a else None, "key" if in_b else None))
            else:
                _diff_values(a[key], b[key], path, (*keys, key), report, rtol, atol)
    elif kind_a == "list":
        if len(a) != len(b):
            report(Difference(path, "shape", keys or None, (len(a),), (len(b),)))
        else:
            for i, (x, y) in enumerate(zip(a, b)):
                _diff_values(x, y, path, (*keys, i), report, rtol, atol)
    elif kind_a == "array":
        a, b = np.asarray(a), np.asarray(b)
        kind = _dtype_kind(a.dtype)
        if a.shape != b.shape:
            report(Difference(path, "shape", keys or None, a.shape, b.shape))
        elif kind != _dtype_kind(b.dtype):
            report(Difference(path, "dtype", keys or None, kind, _dtype_kind(b.dtype)))
        else:
            bad = _mismatch(a, b, kind, rtol, atol)
            if len(bad):
                i = np.unravel_index(bad[0], a.shape)
                index = (*keys, *(int(j) for j in i))
                report(Difference(path, "value", index, _scalar(a[i]), _scalar(b[i]), len(bad), a.size))
    elif len(_mismatch(a, b, kind_a, rtol, atol)):
        report(Difference(path, "value", keys or None, _scalar(a), _scalar(b)))
