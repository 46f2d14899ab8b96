"""Validation of untrusted HDF5 files before anything reads them (docs/security.md).

viscx files travel between people and machines, so a reader trusts nothing in them:

- :func:`check_structure` (run when a file is opened, metadata only): no external or
  soft links, no external raw storage, no virtual datasets (each would read another
  file), only numeric or string dtypes, only the filters viscx writes, and every
  dataset's declared size bounded by the storage it really has in the file and by
  the memory budget (a dataset declared (2^31,) but never written is refused before
  a byte is read).
- :func:`read_arrays` (run when a level is read): every dataset present, of its
  dtype kind and shape (symbolic sizes shared across datasets), finite where it must
  be, ids in range (by kind where the id's meaning depends on a kind column), CSR
  offsets monotone and closing on their flat array.
- :func:`check_scene` : the half-edge structure of a stored scene (loops that close,
  ``next``/``end``/``face``/``loop``/``edge``/``opp`` consistent with the loops), so
  that the numba kernels never walk a broken loop.

Every refusal is a :class:`ViscxError` with one line naming the file and the dataset.
Cost: vectorised numpy passes over each array once (measured in docs/security.md).
"""

from __future__ import annotations

import json
import math
import os

import h5py
import numpy as np
from h5py import h5d, h5l, h5o, h5z

from viscx.arrays import bounding_diagonal
from viscx.errors import ViscxError
from viscx.memory import memory_budget
from viscx.tolerances import MAX_RELATIVE_EPSILON

#: deflate's largest compression ratio is about 1032:1; LZF's is below it
MAX_RATIO = 1100
#: objects in one file (groups and datasets): a metadata bomb is refused before it is walked
MAX_OBJECTS = 100_000
#: nesting of any JSON text viscx reads from a file (options, counts, scenes)
MAX_JSON_DEPTH = 64


def damaged(path, where, what):
    """The one-line error for a damaged file: names the file and the dataset."""
    if what == "missing":
        return ViscxError(f"{path} is a damaged viscx file (missing {where})")
    return ViscxError(f"{path} is a damaged viscx file ({where}: {what})")


# --------------------------------------------------------------------------------------
# JSON with bounded depth


def json_depth(value, limit=MAX_JSON_DEPTH):
    """The nesting depth of a parsed JSON value, or ``limit + 1`` once it exceeds ``limit``
    (iterative: a deep value cannot overflow the stack here)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > limit:
            return limit + 1
        deepest = max(deepest, depth)
        if isinstance(item, dict):
            stack.extend((v, depth + 1) for v in item.values())
        elif isinstance(item, list):
            stack.extend((v, depth + 1) for v in item)
    return deepest


def load_json(text, what, limit=MAX_JSON_DEPTH):
    """``json.loads`` for untrusted text: ViscxError (naming ``what``) for text that is not
    JSON or nests deeper than ``limit`` (the parser's RecursionError never escapes)."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    if not isinstance(text, str):
        raise ViscxError(f"{what} is not JSON text")
    try:
        value = json.loads(text)
    except RecursionError:
        raise ViscxError(f"{what} nests deeper than {limit} levels") from None
    except ValueError as exc:
        raise ViscxError(f"{what} is not JSON ({exc})") from None
    if json_depth(value, limit) > limit:
        raise ViscxError(f"{what} nests deeper than {limit} levels")
    return value


# --------------------------------------------------------------------------------------
# Structure: links, storage, sizes (metadata only)


def check_structure(h5, path, budget=None):
    """Refuse what would make a reader touch another file or allocate more than the file holds.

    Parameters
    ----------
    h5 : h5py.File
    path : str or Path
        For messages.
    budget : int, optional
        Bytes any one dataset may take in memory (default :func:`viscx.memory.memory_budget`).
    """
    budget = memory_budget() if budget is None else budget
    file_size = os.path.getsize(h5.filename)
    links = []

    # HDF5's own walks (H5Lvisit, H5Ovisit) with the link and object types they report,
    # not h5py's visititems: that opens a Python object per name (a lookup, a link query
    # and a type query each), most of the cost of opening a small file (a 118-object
    # file: 26 -> 8 ms of CPU per check)
    def link(name, info):  # every link, without following it; stops at the first bad one
        links.append(name)
        if info.type != h5l.TYPE_HARD or len(links) > MAX_OBJECTS:
            return name

    bad = h5.id.links.visit(link, info=True)
    if bad is not None:
        bad = bad.decode("utf-8", "replace")
        target = h5.get(bad, getlink=True)
        if isinstance(target, h5py.ExternalLink):
            raise damaged(path, f"/{bad}", f"an external link to {target.filename!r}; viscx reads no other file")
        if isinstance(target, h5py.SoftLink):
            raise damaged(path, f"/{bad}", "a soft link; viscx files have none")
        raise damaged(path, f"/{bad}", f"more than {MAX_OBJECTS} objects")

    def check(name, info):  # each object once (HDF5 skips objects it has visited: no cycles)
        if info.type == h5o.TYPE_DATASET:
            _check_dataset(h5d.open(h5.id, name), f"/{name.decode('utf-8', 'replace')}", path, file_size, budget)

    try:
        h5o.visit(h5.id, check, info=True)
    except (KeyError, OSError, RuntimeError) as exc:
        raise ViscxError(f"{path} is a damaged viscx file (unreadable structure: {str(exc)[:120]})") from None


_FILTERS = {h5z.FILTER_DEFLATE: "gzip", h5z.FILTER_SHUFFLE: "shuffle", h5z.FILTER_FLETCHER32: "fletcher32",
            h5z.FILTER_LZF: "lzf"}


def _check_dataset(d, where, path, file_size, budget):
    """``d`` : h5py.h5d.DatasetID (HDF5's handle: its plist, type, space and storage)."""
    dcpl = d.get_create_plist()
    if dcpl.get_layout() == h5d.VIRTUAL:
        raise damaged(path, where, "a virtual dataset; viscx reads no other file")
    if dcpl.get_external_count():
        raise damaged(path, where, "external raw storage; viscx reads no other file")
    dtype = d.dtype
    if not (dtype.kind in "biuf" or h5py.check_string_dtype(dtype) is not None):
        raise damaged(path, where, f"dtype {dtype} is neither a number nor a string")
    filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())]
    unknown = [code for code in filters if code not in _FILTERS]
    if unknown:
        raise damaged(path, where, f"filter {unknown[0]} is not one viscx reads")
    compressed = h5z.FILTER_DEFLATE in filters or h5z.FILTER_LZF in filters
    shape = d.shape
    declared = math.prod(shape) * dtype.itemsize if shape is not None else 0
    storage = d.get_storage_size()
    if storage > file_size:
        raise damaged(path, where, f"claims {storage} bytes of storage in a file of {file_size}")
    if declared > storage * (MAX_RATIO if compressed else 1):
        raise damaged(path, where, f"shape {shape} declares {declared} bytes but the file holds {storage}")
    if declared > budget:
        raise damaged(path, where, f"shape {shape} needs {declared / 2**30:.1f} GiB, over the memory budget "
                      f"({budget / 2**30:.1f} GiB; VISCX_MEMORY_BUDGET)")


# --------------------------------------------------------------------------------------
# Attributes

LEVELS = ("scene", "V0", "V1", "V2")
#: the root attributes every viscx file has (docs/format.md); readers use each of them
ROOT_ATTRIBUTES = ("format", "format_version", "viscx_version", "epsilon", "weld_tolerance", "scene_sha256",
                   "scene_name", "options", "levels")
#: those of them that are text
TEXT_ATTRIBUTES = ("viscx_version", "scene_sha256", "scene_name", "options", "levels")
#: attributes of level groups that map names to integer codes or counts
_CODE_ATTRIBUTES = ("kinds", "blocker_kinds", "end_types", "element_kinds", "counts")


def check_attributes(h5, path):
    """The root attributes a reader uses and the levels they name (after the format and
    version checks of :class:`viscx.formats.hdf5.ViscxFile`). Returns ``(levels, options)``."""
    attrs = h5.attrs
    for name in ROOT_ATTRIBUTES:
        if name not in attrs:
            raise damaged(path, f"@{name}", "missing")
    for name in TEXT_ATTRIBUTES:
        if not isinstance(attrs[name], str):
            raise damaged(path, f"@{name}", f"{attrs[name]!r:.40} is not text")
    for name in ("epsilon", "weld_tolerance"):
        value = attrs[name]
        if not (np.ndim(value) == 0 and np.asarray(value).dtype.kind in "iuf" and np.isfinite(value) and value >= 0):
            raise damaged(path, f"@{name}", f"{value!r} is not a finite number >= 0")
    if not attrs["epsilon"] > 0:
        raise damaged(path, "@epsilon", "must be > 0")
    levels = load_json(attrs["levels"], f"{path}: attribute levels")
    options = load_json(attrs["options"], f"{path}: attribute options")
    if not isinstance(options, dict):
        raise damaged(path, "@options", "not a JSON object")
    if not (isinstance(levels, list) and levels[:1] == ["scene"] and all(x in LEVELS for x in levels)
            and sorted(levels, key=LEVELS.index) == levels and len(set(levels)) == len(levels)):
        raise damaged(path, "@levels", f"{str(levels)[:80]} is not 'scene' and levels above it in order")
    for level in levels:
        if not isinstance(h5.get(level), h5py.Group):
            raise damaged(path, f"/{level}", "listed in the attribute levels but missing")
    if "V2" in levels and not isinstance(h5.get("V1"), h5py.Group):  # V2's readers read V1's arcs
        raise damaged(path, "/V1", "missing, but V2 is listed (its cells are bounded by V1's arcs)")
    provenance = h5.get("provenance")
    if isinstance(provenance, h5py.Group) and "timings" in provenance.attrs:
        timings = load_json(provenance.attrs["timings"], f"{path}: attribute /provenance@timings")
        if not (isinstance(timings, dict)
                and all(type(v) in (int, float) and np.isfinite(v) for v in timings.values())):
            raise damaged(path, "/provenance@timings", "not a JSON object of seconds")
    for level in (*levels, "V2/ee"):
        group = h5.get(level)
        if not isinstance(group, h5py.Group):
            continue
        for name in _CODE_ATTRIBUTES:
            if name in group.attrs:
                value = load_json(group.attrs[name], f"{path}: attribute /{level}@{name}")
                if not (isinstance(value, dict) and all(type(v) is int for v in value.values())):
                    raise damaged(path, f"/{level}@{name}", "not a JSON object of integers")
    return levels, options


# --------------------------------------------------------------------------------------
# Content: presence, dtype, shape, ranges


class Checker:
    """Reads datasets of one group and checks them against a schema.

    Symbolic sizes (``"n"``, ``"f+1"``) are shared across every dataset the checker
    reads: the first dataset that names a size defines it, the others must agree.
    """

    def __init__(self, path, sizes=None):
        self.path = path
        self.sizes = dict(sizes or {})

    def fail(self, where, what):
        raise damaged(self.path, where, what)

    def read(self, group, name, kind, dims, finite=True, default=None):
        """One dataset as an array of its kind: ``kind`` "f" float64, "i" int64, "b" bool,
        "s" str list; ``dims`` a tuple of ints and symbols (``"n"``, ``"n+1"``)."""
        where = f"{group.name.rstrip('/')}/{name}"
        obj = group.get(name)
        if obj is None:
            if default is not None:
                return default(self)
            self.fail(where, "missing")
        if not isinstance(obj, h5py.Dataset):
            self.fail(where, "not a dataset")
        shape = obj.shape
        if shape is None or len(shape) != len(dims):
            self.fail(where, f"shape {shape}, expected {len(dims)} dimensions")
        for size, dim in zip(shape, dims):
            self._dim(where, size, dim)
        try:
            if kind == "s":
                if h5py.check_string_dtype(obj.dtype) is None:
                    self.fail(where, f"dtype {obj.dtype}, expected strings")
                return [s if isinstance(s, str) else str(s) for s in obj.asstr(errors="replace")[()]]
            data = obj[()]
        except (OSError, ValueError, TypeError) as exc:
            raise damaged(self.path, where, f"unreadable ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
        return self.convert(where, data, kind, finite)

    def convert(self, where, data, kind, finite=True):
        data = np.asarray(data)
        if kind == "f":
            if data.dtype.kind != "f":
                self.fail(where, f"dtype {data.dtype}, expected float")
            if finite and data.size and not np.isfinite(data).all():
                self.fail(where, "a NaN or infinite value")
            return data.astype(np.float64, copy=False)
        if kind == "i":
            if data.dtype.kind not in "iu":
                self.fail(where, f"dtype {data.dtype}, expected integers")
            if data.dtype.kind == "u" and data.size and data.max() > np.iinfo(np.int64).max:
                self.fail(where, "a value beyond int64")
            return data.astype(np.int64, copy=False)
        if kind == "b":
            if data.dtype.kind != "b":
                self.fail(where, f"dtype {data.dtype}, expected bool")
            return data
        raise ValueError(kind)

    def _dim(self, where, size, dim):
        if isinstance(dim, int):
            if size != dim:
                self.fail(where, f"size {size} where {dim} belongs")
            return
        symbol, _, plus = dim.partition("+")
        plus = int(plus or 0)
        if symbol not in self.sizes:
            if size < plus:
                self.fail(where, f"size {size}, expected at least {plus}")
            self.sizes[symbol] = size - plus
        elif size != self.sizes[symbol] + plus:
            self.fail(where, f"size {size}, expected {self.sizes[symbol] + plus} ({dim})")

    # value rules ----------------------------------------------------------------------

    def inside_box(self, where, points, box):
        """Every point (..., 3) inside ``box`` = (lo, hi) (skipped when box is None)."""
        if box is None or not points.size:
            return
        pts = points.reshape(-1, 3)
        out = np.any((pts < box[0]) | (pts > box[1]), axis=1)
        if out.any():
            self.fail(where, f"point {pts[np.argmax(out)].tolist()} far outside the scene")

    def within(self, where, values, low, high):
        """Every value in [low, high)."""
        if values.size and (values.min() < low or values.max() >= high):
            bad = values[(values < low) | (values >= high)].flat[0]
            self.fail(where, f"value {bad} out of range [{low}, {high})")

    def by_kind(self, where, ids, kinds, ranges, kinds_where=None):
        """ids whose meaning depends on a kind column: ``ranges`` ``{kind: (low, high)}``;
        a kind not in ``ranges`` is refused."""
        known = np.isin(kinds, list(ranges))
        if not known.all():
            self.fail(kinds_where or where, f"unknown kind {kinds[~known].flat[0]}")
        for kind, (low, high) in ranges.items():
            self.within(where, ids[kinds == kind], low, high)

    def offsets(self, where, offsets, total, strict=False):
        """A CSR offset list over a flat array of ``total`` items (``strict``: every row non-empty)."""
        steps = np.diff(offsets)
        if offsets[0] != 0 or offsets[-1] != total or (steps.size and steps.min() < (1 if strict else 0)):
            self.fail(where, f"not a CSR offset list over {total} items")


# --------------------------------------------------------------------------------------
# The scene


def scene_arrays(group, path):
    """The datasets of ``/scene``, checked (shapes, dtypes, ranges, finite floats, the
    half-edge loops). Returns ``(arrays, half_edges, edges, names)``: dicts of arrays and
    the group and material names."""
    c = Checker(path)
    a = {
        "vertices": c.read(group, "vertices", "f", ("n", 3)),
        "face_area": c.read(group, "face_area", "f", ("f",)),
        "face_loop_offsets": c.read(group, "face_loop_offsets", "i", ("f+1",)),
        "loop_offsets": c.read(group, "loop_offsets", "i", ("l+1",)),
        "loop_vertices": c.read(group, "loop_vertices", "i", ("h",)),
        "triangles": c.read(group, "triangles", "i", ("t", 3)),
        "triangle_face": c.read(group, "triangle_face", "i", ("t",)),
        "face_normal": c.read(group, "face_normal", "f", ("f", 3)),
        "face_offset": c.read(group, "face_offset", "f", ("f",)),
        "face_group": c.read(group, "face_group", "i", ("f",)),
        "face_material": c.read(group, "face_material", "i", ("f",)),
        "material_kd": c.read(group, "material_kd", "f", ("k", 3)),
        "material_ke": c.read(group, "material_ke", "f", ("k", 3)),
    }
    names = c.read(group, "group_names", "s", ("g",))
    materials = c.read(group, "material_names", "s", ("k",))
    he = {name: c.read(group, f"half_edges/{name}", "i", ("h",)) for name in
          ("start", "end", "face", "next", "opp", "edge", "loop")}
    edges = {
        "edge_vertices": c.read(group, "edges/vertices", "i", ("e", 2)),
        "edge_is_generator": c.read(group, "edges/is_generator", "b", ("e",)),
        "vertex_is_generator": c.read(group, "vertex_is_generator", "b", ("n",)),
    }
    check_scene(c, a, he, edges)
    # as the scene's builder writes them: welding at the scene's size leaves no face, and
    # epsilon is at most MAX_RELATIVE_EPSILON of it
    diagonal = bounding_diagonal(a["vertices"])
    for name, most in (("weld_tolerance", 1.0), ("epsilon", MAX_RELATIVE_EPSILON)):
        if float(group.file.attrs[name]) > most * diagonal:
            c.fail(f"/@{name}", f"{float(group.file.attrs[name]):g} is larger than {most:g} of the scene's size")
    _check_generators(c, a, he, edges, float(group.file.attrs["weld_tolerance"]))
    return a, he, edges, names, materials


def _check_generators(c, a, he, edges, tolerance):
    """The edges and generator flags are a function of the checked loops, normals and the
    weld tolerance: rebuilt as the scene's cleaning builds them, they must be the stored
    ones (a generator flag flipped sends the kernels into families with nothing to hold)."""
    from viscx.scene.halfedge import build_half_edges

    rebuilt = build_half_edges(a["vertices"], a["face_normal"], a["face_loop_offsets"], a["loop_offsets"],
                               a["loop_vertices"], tolerance)
    for name, where in (("edge_vertices", "/scene/edges/vertices"), ("opp", "/scene/half_edges/opp"),
                        ("edge", "/scene/half_edges/edge"), ("edge_is_generator", "/scene/edges/is_generator"),
                        ("vertex_is_generator", "/scene/vertex_is_generator")):
        stored = edges.get(name, he.get(name))
        if not np.array_equal(stored, getattr(rebuilt, name)):
            c.fail(where, "does not match the scene's loops (rebuilt from them)")


def check_scene(c, a, he, edges):
    """Ranges and the half-edge structure of a stored scene (see docs/format.md)."""
    s = c.sizes
    n, f, t, h, e, k, g = (s[x] for x in "nfthekg")
    w = "/scene/"
    if f == 0:
        c.fail(w + "face_area", "the scene has no faces")
    c.within(w + "triangles", a["triangles"], 0, n)
    c.within(w + "triangle_face", a["triangle_face"], 0, f)
    c.within(w + "loop_vertices", a["loop_vertices"], 0, n)
    c.within(w + "face_group", a["face_group"], 0, g)
    c.within(w + "face_material", a["face_material"], -1, k)
    c.offsets(w + "face_loop_offsets", a["face_loop_offsets"], s["l"], strict=True)
    c.offsets(w + "loop_offsets", a["loop_offsets"], h)
    if np.diff(a["loop_offsets"]).min(initial=3) < 3:
        c.fail(w + "loop_offsets", "a loop of fewer than 3 vertices")
    if a["face_area"].min(initial=0) < 0:
        c.fail(w + "face_area", "a negative area")
    if not np.isfinite(bounding_diagonal(a["vertices"])):  # as the scene's builder refuses them
        c.fail(w + "vertices", "coordinates too large (the bounding box overflows float64)")
    if np.abs(np.linalg.norm(a["face_normal"], axis=1) - 1).max(initial=0) > 1e-6:
        c.fail(w + "face_normal", "a normal that is not a unit vector")
    # the half-edges are determined by the loops: h leaves loop_vertices[h], next is the
    # following position of its loop (the loop's first after its last)
    loop = np.repeat(np.arange(s["l"]), np.diff(a["loop_offsets"]))
    pos = np.arange(h)
    nxt = np.where(pos + 1 == a["loop_offsets"][loop + 1], a["loop_offsets"][loop], pos + 1)
    face = np.repeat(np.arange(f), np.diff(a["face_loop_offsets"]))[loop]
    w = "/scene/half_edges/"
    for name, expect in (("next", nxt), ("loop", loop), ("start", a["loop_vertices"]),
                         ("end", a["loop_vertices"][nxt]), ("face", face)):
        if not np.array_equal(he[name], expect):
            c.fail(w + name, "does not follow the loops (a loop that does not close)")
    c.within(w + "edge", he["edge"], 0, e)
    ev = edges["edge_vertices"]
    c.within("/scene/edges/vertices", ev, 0, n)
    if e and np.any(ev[:, 0] >= ev[:, 1]):
        c.fail("/scene/edges/vertices", "an edge that is not (smaller, larger) vertex id")
    ends = np.sort(np.stack([he["start"], he["end"]], axis=1), axis=1)
    if not np.array_equal(ev[he["edge"]], ends):
        c.fail(w + "edge", "names an edge with other vertices")
    opp = he["opp"]
    c.within(w + "opp", opp, -1, h)
    paired = np.flatnonzero(opp >= 0)
    if np.any(opp[opp[paired]] != paired) or np.any(he["edge"][opp[paired]] != he["edge"][paired]) or np.any(opp[paired] == paired):
        c.fail(w + "opp", "not a pairing of the half-edges of one edge")


#: the bound of ids into a group the file lacks (a level read from a partial file, as tests
#: write them): only their sign is checked. Files opened by ViscxFile hold every level below
#: the ones they list (check_attributes), so their ids are bounded.
UNBOUNDED = 2**62


def scene_sizes(h5):
    """The sizes level checks need from the scene, from shapes only: n vertices, p
    generator vertex ids (vertices and free points), f faces, e edges."""
    n = _rows(h5, "scene/vertices")
    points = _rows(h5, "scene/points") if "scene/points" in h5 else 0
    return {"n_vertices": n, "p": min(n + points, UNBOUNDED), "faces": _rows(h5, "scene/face_area"),
            "edges": _rows(h5, "scene/edges/vertices"), "box": _segment_box(h5)}


def _segment_box(h5):
    """(lo, hi) (3,) float64 that every stored segment end lies in: the scene's box (with its
    free points) grown by its diagonal (sky ends sit 1 % outside it; docs/format.md), or
    None when the scene's vertices cannot give one (the scene's own checks say why)."""
    try:
        v = np.asarray(h5["scene/vertices"][()], dtype=np.float64).reshape(-1, 3)
        if "scene/points" in h5:
            v = np.concatenate([v, np.asarray(h5["scene/points"][()], dtype=np.float64).reshape(-1, 3)])
    except (KeyError, TypeError, ValueError):
        return None
    if not len(v) or not np.all(np.isfinite(v)):
        return None
    lo, hi = v.min(axis=0), v.max(axis=0)
    grow = float(np.linalg.norm(hi - lo)) + 1.0
    return lo - grow, hi + grow


# --------------------------------------------------------------------------------------
# The levels (docs/format.md)

FACE, SKY, EDGE, VERTEX = 0, 1, 2, 3


def _blockers(c, where, blocker, kind, sizes, kinds=(FACE, SKY, EDGE, VERTEX)):
    table = {FACE: (0, sizes["faces"]), SKY: (-1, 0), EDGE: (0, sizes["edges"]), VERTEX: (0, sizes["p"])}
    c.by_kind(where, blocker, kind, {k: table[k] for k in kinds}, where + "_kind")


def node_arrays(group, path, sizes):
    """The datasets of a ``V0`` group (or ``V1/planar``), checked."""
    c = Checker(path)
    w = group.name.rstrip("/") + "/"
    a = {"kind": c.read(group, "kind", "i", ("m",)).astype(np.int8),
         "generators": c.read(group, "generators", "i", ("m", 4)),
         "direction": c.read(group, "direction", "f", ("m", 3)),
         "ends": c.read(group, "ends", "f", ("m", 2, 3)),
         "blocker_kind": c.read(group, "blocker_kind", "i", ("m", 2)).astype(np.int8),
         "blocker": c.read(group, "blocker", "i", ("m", 2)),
         "generator_points": c.read(group, "generator_points", "f", ("m", 4, 3), finite=False)}
    kind, gen = a["kind"], a["generators"]
    c.within(w + "kind", kind, 0, 3)
    c.inside_box(w + "ends", a["ends"], sizes.get("box"))
    v, e = (0, sizes["p"]), (0, sizes["edges"])
    columns = {0: (e, e, e, e), 1: (v, e, e, (-1, 0)), 2: (v, v, (-1, 0), (-1, 0))}  # E4, VEE, VV
    for k, cols in columns.items():
        rows = gen[kind == k]
        for j, (low, high) in enumerate(cols):
            c.within(w + "generators", rows[:, j], low, high)
    _blockers(c, w + "blocker", a["blocker"], a["blocker_kind"], sizes)
    return a


def arc_arrays(group, path, sizes):
    """The datasets of a ``V1`` group, checked (its ``planar`` nodes and ``half_cells`` too).
    Returns ``(arcs, planar, half_cells)``."""
    c = Checker(path)
    w = "/V1/"
    a = {"kind": c.read(group, "kind", "i", ("m",)).astype(np.int8),
         "generators": c.read(group, "generators", "i", ("m", 3)),
         "interval": c.read(group, "interval", "f", ("m", 2)),
         "end_type": c.read(group, "end_type", "i", ("m", 2)).astype(np.int8),
         "end_node": c.read(group, "end_node", "i", ("m", 2)),
         "blocker_kind": c.read(group, "blocker_kind", "i", ("m", 2)).astype(np.int8),
         "blocker": c.read(group, "blocker", "i", ("m", 2)),
         "parameter": c.read(group, "parameter", "f", ("m",)),
         "direction": c.read(group, "direction", "f", ("m", 3)),
         "ends": c.read(group, "ends", "f", ("m", 2, 3)),
         "generator_points": c.read(group, "generator_points", "f", ("m", 3, 3), finite=False)}
    planar_group = group.get("planar")
    if not isinstance(planar_group, h5py.Group):
        c.fail(w + "planar", "missing")
    planar = node_arrays(planar_group, path, sizes)
    n_nodes = _rows(group.file, "V0/kind")
    kind, gen = a["kind"], a["generators"]
    c.within(w + "kind", kind, 0, 3)
    c.inside_box(w + "ends", a["ends"], sizes.get("box"))
    v, e = (0, sizes["p"]), (0, sizes["edges"])
    for k, cols in {0: (e, e, e), 1: (v, e, (-1, 0)), 2: (e, e, e)}.items():  # EEE, VE, XE
        rows = gen[kind == k]
        for j, (low, high) in enumerate(cols):
            c.within(w + "generators", rows[:, j], low, high)
    ends = _end_ranges(sizes, n_nodes, len(planar["kind"]))
    c.by_kind(w + "end_node", a["end_node"], a["end_type"], ends, w + "end_type")
    _blockers(c, w + "blocker", a["blocker"], a["blocker_kind"], sizes)
    hg = group.get("half_cells")
    if not isinstance(hg, h5py.Group):
        c.fail(w + "half_cells", "missing")
    w += "half_cells/"
    hc = {"arc": c.read(hg, "arc", "i", ("h",)), "vertex": c.read(hg, "vertex", "i", ("h",)),
          "edge": c.read(hg, "edge", "i", ("h",)),
          "up_kind": c.read(hg, "up_kind", "i", ("h", 2)).astype(np.int8), "up": c.read(hg, "up", "i", ("h", 2)),
          "down_kind": c.read(hg, "down_kind", "i", ("h", 2)).astype(np.int8),
          "down": c.read(hg, "down", "i", ("h", 2)),
          "start": c.read(hg, "start", "i", ("h",)), "end": c.read(hg, "end", "i", ("h",)),
          "start_type": c.read(hg, "start_type", "i", ("h",)).astype(np.int8),
          "end_type": c.read(hg, "end_type", "i", ("h",)).astype(np.int8)}
    c.within(w + "arc", hc["arc"], 0, c.sizes["m"])
    c.within(w + "vertex", hc["vertex"], *v)
    c.within(w + "edge", hc["edge"], *e)
    _blockers(c, w + "up", hc["up"], hc["up_kind"], sizes)
    _blockers(c, w + "down", hc["down"], hc["down_kind"], sizes)
    c.by_kind(w + "start", hc["start"], hc["start_type"], ends, w + "start_type")
    c.by_kind(w + "end", hc["end"], hc["end_type"], ends, w + "end_type")
    return a, planar, hc


def _end_ranges(sizes, n_nodes, n_planar):
    """What ``end_node`` names for each end type (docs/format.md, ``/V1``)."""
    e, p = (0, sizes["edges"]), (-1, sizes["p"])
    return {0: (0, n_nodes), 1: (0, n_planar), 2: (-1, 0), 3: (-1, 0), 4: e, 5: p, 6: p, 7: e}


def _rows(h5, name):
    """Rows of a dataset the checks bound ids by (UNBOUNDED when the file lacks it)."""
    obj = h5.get(name)
    if not isinstance(obj, h5py.Dataset):
        return UNBOUNDED
    return int(obj.shape[0]) if obj.shape else 0


def vcell_arrays(group, path, sizes):
    """The datasets of a ``V2`` group's V-cells (and ``open/``), checked; keys as
    :class:`viscx.skeleton.vcells.VCells` (``open_*`` for the open chains)."""
    c = Checker(path)
    n_half = _rows(group.file, "V1/half_cells/arc")
    a = {"vertex": c.read(group, "vertex", "i", ("c",)),
         "up_kind": c.read(group, "up_kind", "i", ("c",)).astype(np.int8), "up": c.read(group, "up", "i", ("c",)),
         "down_kind": c.read(group, "down_kind", "i", ("c",)).astype(np.int8),
         "down": c.read(group, "down", "i", ("c",)),
         "solid_angle": c.read(group, "solid_angle", "f", ("c",)), "twin": c.read(group, "twin", "i", ("c",)),
         "complete": c.read(group, "complete", "b", ("c",)),
         "loop_offsets": c.read(group, "loop_offsets", "i", ("c+1",)), "turning": c.read(group, "turning", "f", ("l",)),
         "element_offsets": c.read(group, "element_offsets", "i", ("l+1",)),
         "element": c.read(group, "element", "i", ("k",)), "antipodal": c.read(group, "antipodal", "b", ("k",))}
    og = _subgroup(c, group, "open")
    a.update({"open_offsets": c.read(og, "offsets", "i", ("o+1",)), "open_element": c.read(og, "element", "i", ("q",)),
              "open_antipodal": c.read(og, "antipodal", "b", ("q",)), "open_vertex": c.read(og, "vertex", "i", ("o",)),
              "open_up_kind": c.read(og, "up_kind", "i", ("o",)).astype(np.int8), "open_up": c.read(og, "up", "i", ("o",)),
              "open_down_kind": c.read(og, "down_kind", "i", ("o",)).astype(np.int8),
              "open_down": c.read(og, "down", "i", ("o",))})
    s = c.sizes
    for prefix, w in (("", "/V2/"), ("open_", "/V2/open/")):
        c.within(w + "vertex", a[prefix + "vertex"], 0, sizes["p"])
        _blockers(c, w + "up", a[prefix + "up"], a[prefix + "up_kind"], sizes, (FACE, SKY, VERTEX))
        _blockers(c, w + "down", a[prefix + "down"], a[prefix + "down_kind"], sizes, (FACE, SKY))
        _signed(c, w + "element", a[prefix + "element"], n_half)
    c.within("/V2/twin", a["twin"], -1, s["c"])
    c.offsets("/V2/loop_offsets", a["loop_offsets"], s["l"])
    c.offsets("/V2/element_offsets", a["element_offsets"], s["k"])
    c.offsets("/V2/open/offsets", a["open_offsets"], s["q"])
    return a


def _subgroup(c, group, name):
    sub = group.get(name)
    if not isinstance(sub, h5py.Group):
        c.fail(f"{group.name}/{name}", "missing")
    return sub


def _signed(c, where, element, count):
    """Signed ids ±(i+1) of rows i < count."""
    magnitude = np.abs(element)
    c.within(where, magnitude, 1, count + 1)


def eecell_arrays(group, path, sizes):
    """The datasets of ``V2/ee`` (and ``open/``), checked; keys as
    :class:`viscx.skeleton.eecells.EECells`. Files written before the square sides have
    no ``element_kind``: every element there is an arc."""
    c = Checker(path)
    n_arcs = _rows(group.file, "V1/kind")

    def arcs_only(name, size):
        return lambda checker: np.zeros(checker.sizes[size], np.int64)

    a = {"edge1": c.read(group, "edge1", "i", ("c",)), "edge2": c.read(group, "edge2", "i", ("c",)),
         "back_kind": c.read(group, "back_kind", "i", ("c",)).astype(np.int8), "back": c.read(group, "back", "i", ("c",)),
         "front_kind": c.read(group, "front_kind", "i", ("c",)).astype(np.int8),
         "front": c.read(group, "front", "i", ("c",)), "area": c.read(group, "area", "f", ("c",)),
         "complete": c.read(group, "complete", "b", ("c",)),
         "loop_offsets": c.read(group, "loop_offsets", "i", ("c+1",)), "turning": c.read(group, "turning", "f", ("l",)),
         "element_offsets": c.read(group, "element_offsets", "i", ("l+1",)),
         "element": c.read(group, "element", "i", ("k",)),
         "element_kind": c.read(group, "element_kind", "i", ("k",), default=arcs_only("element_kind", "k")),
         "element_interval": c.read(group, "element_interval", "f", ("k", 2))}
    og = _subgroup(c, group, "open")
    a.update({"open_offsets": c.read(og, "offsets", "i", ("o+1",)), "open_element": c.read(og, "element", "i", ("q",)),
              "open_element_kind": c.read(og, "element_kind", "i", ("q",), default=arcs_only("element_kind", "q")),
              "open_interval": c.read(og, "interval", "f", ("q", 2)),
              **{f"open_{name}": c.read(og, name, "i", ("o",)) for name in
                 ("edge1", "edge2", "back_kind", "back", "front_kind", "front")}})
    for name in ("element_kind", "open_element_kind", "back_kind", "front_kind", "open_back_kind", "open_front_kind"):
        a[name] = a[name].astype(np.int8)
    s = c.sizes
    for prefix, w, kind, size in (("", "/V2/ee/", "element_kind", "k"), ("open_", "/V2/ee/open/", "open_element_kind", "q")):
        c.within(w + "edge1", a[prefix + "edge1"], 0, sizes["edges"])
        c.within(w + "edge2", a[prefix + "edge2"], 0, sizes["edges"])
        _blockers(c, w + "back", a[prefix + "back"], a[prefix + "back_kind"], sizes, (FACE, SKY, EDGE))
        _blockers(c, w + "front", a[prefix + "front"], a[prefix + "front_kind"], sizes, (FACE, SKY, EDGE))
        element = a["element" if not prefix else "open_element"]
        # arc: a /V1 arc; side: one of the square's 4 sides; pencil1/2: an edge
        c.by_kind(w + "element", np.abs(element), a[kind], {0: (1, n_arcs + 1), 1: (1, 5), 2: (1, sizes["edges"] + 1),
                                                            3: (1, sizes["edges"] + 1)}, w + "element_kind")
    c.offsets("/V2/ee/loop_offsets", a["loop_offsets"], s["l"])
    c.offsets("/V2/ee/element_offsets", a["element_offsets"], s["k"])
    c.offsets("/V2/ee/open/offsets", a["open_offsets"], s["q"])
    return a


def points_array(group, path):
    """``/scene/points`` (free points of ``viscx build --point``), checked; (0, 3) when absent."""
    if "points" not in group:
        return np.zeros((0, 3))
    return Checker(path).read(group, "points", "f", ("k", 3))
