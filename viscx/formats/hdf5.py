"""The viscx HDF5 container: one group per skeleton level.

Layout (every dataset is documented in ``docs/format.md``)::

    /                 attrs: format="viscx", format_version, viscx_version,
                             epsilon, weld_tolerance, scene_sha256, scene_name,
                             options (JSON), levels (JSON list of level names)
    /scene            the cleaned scene (vertices, faces as loops, triangles, groups,
                      materials) with subgroups half_edges/ and edges/
    /provenance       attrs: timings (JSON); the only part that changes between
                      two builds of the same input (``viscx diff`` ignores it)

Files are written through a temporary file renamed on success
(:func:`viscx.formats.atomic.atomic_path`). Datasets carry no timestamps, so
the same scene and options give the same content.
"""

import contextlib
import contextvars
import json
from pathlib import Path

import h5py
import numpy as np

from viscx import __version__
from viscx.errors import ViscxError
from viscx.formats import validate
from viscx.formats.atomic import atomic_path, register_input
from viscx.formats.compression import COMPRESSIONS, DEFAULT_COMPRESSION
from viscx.scene import Scene
from viscx.scene.halfedge import HalfEdges

FORMAT = "viscx"
FORMAT_VERSION = 1

_SCENE_ARRAYS = [
    "vertices",
    "triangles",
    "triangle_face",
    "face_loop_offsets",
    "loop_offsets",
    "loop_vertices",
    "face_normal",
    "face_offset",
    "face_area",
    "face_group",
    "face_material",
    "material_kd",
    "material_ke",
]
_HALF_EDGE_ARRAYS = ["start", "end", "face", "next", "opp", "edge", "loop"]
_REQUIRED_ATTRS = ["levels", "options", "epsilon", "weld_tolerance"]
_STRINGS = h5py.string_dtype(encoding="utf-8")


#: Datasets with fewer values are stored contiguous, unfiltered.
COMPRESS_MIN_SIZE = 4096
#: Bytes per chunk: whole rows (a chunk never splits a node's or an arc's row, which
#: would interleave unlike values), large enough for the coder to find repeats.
CHUNK_BYTES = 1 << 18
# the coder of the file being written (write_complex sets it for its writers)
_compression = contextvars.ContextVar("viscx_compression", default=DEFAULT_COMPRESSION)


def _row_chunks(data):
    """Chunk shape of ``data``: about CHUNK_BYTES of whole rows."""
    row = max(1, data.itemsize * int(np.prod(data.shape[1:], dtype=np.int64)))
    return (int(min(len(data), max(1, CHUNK_BYTES // row))), *data.shape[1:])


def write_dataset(group, name, data, compression=None):
    """Write one array deterministically (no timestamps); an array of at least
    COMPRESS_MIN_SIZE values is chunked by rows and compressed by ``compression`` (a key
    of COMPRESSIONS; default the one of the file being written, else gzip)."""
    data = np.asarray(data)
    kwargs = {"track_times": False}
    coder = COMPRESSIONS[compression or _compression.get()]
    if coder and data.size >= COMPRESS_MIN_SIZE and data.dtype != object:
        kwargs.update(compression=coder[0], compression_opts=coder[1], shuffle=data.dtype.kind != "f",
                      chunks=_row_chunks(data))
    return group.create_dataset(name, data=data, **kwargs)


def write_strings(group, name, strings):
    group.create_dataset(name, data=np.array(list(strings), dtype=object), dtype=_STRINGS, track_times=False)


def _write_scene(group, scene):
    for name in _SCENE_ARRAYS:
        write_dataset(group, name, getattr(scene, name))
    write_strings(group, "group_names", scene.group_names)
    write_strings(group, "material_names", scene.material_names)
    he = group.create_group("half_edges", track_order=True)
    for name in _HALF_EDGE_ARRAYS:
        write_dataset(he, name, getattr(scene.half_edges, name))
    edges = group.create_group("edges", track_order=True)
    write_dataset(edges, "vertices", scene.half_edges.edge_vertices)
    write_dataset(edges, "is_generator", scene.half_edges.edge_is_generator)
    write_dataset(group, "vertex_is_generator", scene.half_edges.vertex_is_generator)


def write_complex(path, scene, levels=None, options=None, timings=None, points=None, compression=DEFAULT_COMPRESSION):
    """Write a viscx file atomically.

    Parameters
    ----------
    path : str or Path
    scene : Scene
    levels : dict, optional
        ``{level_name: writer}``, each writer a callable ``writer(h5py.Group)``
        that fills its level's group (``V0``, ``V1``, ``V2``, ``points``).
    options : dict, optional
        The build options (JSON-serialisable), stored as the ``options`` attribute.
    timings : dict, optional
        Seconds per stage, stored under ``/provenance``.
    points : (k, 3) float64, optional
        Free points added as generators (``viscx build --point``), stored as
        ``/scene/points``; point i is generator vertex ``n_vertices + i``. Nothing is
        written when there are none.
    compression : str
        The filter of the large datasets (a key of COMPRESSIONS). Not stored as content:
        files that differ only in it are equal for ``viscx diff``.
    """
    levels = levels or {}
    with complex_writer(path, scene, list(levels), options, timings, points, compression) as f:
        for name, writer in levels.items():
            writer(f.create_group(name, track_order=True))


@contextlib.contextmanager
def complex_writer(path, scene, level_names, options=None, timings=None, points=None, compression=DEFAULT_COMPRESSION):
    """The open ``h5py.File`` of a viscx file being written, its header and scene written;
    the caller creates the groups of ``level_names`` (list of str, as the ``levels``
    attribute lists them) and fills them, e.g. chunk by chunk as a level is built
    (:class:`Appender`). On exit ``/provenance`` gets ``timings`` (a dict, read then: a
    build's stages may still add to it while the levels are written) and the file is
    renamed into place; an exception leaves nothing behind (:func:`atomic_path`).
    Arguments as :func:`write_complex`."""
    if compression not in COMPRESSIONS:
        raise ViscxError(f"unknown compression {compression!r} (one of {', '.join(COMPRESSIONS)})")
    token = _compression.set(compression)
    try:
        with atomic_path(path) as tmp:
            with h5py.File(tmp, "w", track_order=True) as f:
                _write_header(f, scene, level_names, options, points)
                yield f
                prov = f.create_group("provenance")
                prov.attrs["timings"] = json.dumps(timings or {}, sort_keys=True)
    finally:
        _compression.reset(token)


def _write_header(f, scene, level_names, options, points):
    """The root attributes and ``/scene`` (with ``points``) of a new viscx file."""
    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = FORMAT_VERSION
    f.attrs["viscx_version"] = __version__
    f.attrs["epsilon"] = scene.epsilon
    f.attrs["weld_tolerance"] = scene.weld_tolerance
    f.attrs["scene_sha256"] = scene.sha256
    f.attrs["scene_name"] = Path(scene.source).name if scene.source else ""
    f.attrs["options"] = json.dumps(options or {}, sort_keys=True)
    f.attrs["levels"] = json.dumps(["scene", *level_names])
    _write_scene(f.create_group("scene", track_order=True), scene)
    if points is not None and len(points):
        dset = write_dataset(f["scene"], "points", np.asarray(points, dtype=np.float64).reshape(-1, 3))
        dset.attrs["first_id"] = scene.n_vertices


#: Bytes of one dataset an :class:`Appender` holds before it writes them out.
APPEND_BYTES = 4 * CHUNK_BYTES


class Appender:
    """The datasets of one group, filled by appending rows chunk by chunk (a level built
    in chunks, written as they come: no process holds the whole level).

    Each dataset's rows are held until APPEND_BYTES of them are waiting, then written to
    a resizable dataset (chunked and compressed as :func:`write_dataset` does a large
    one); a dataset that never reaches that size is written whole on :meth:`close` by
    :func:`write_dataset`, as it would have been from memory. The content is the rows in
    the order they were appended: the same as writing their concatenation.

    Parameters
    ----------
    group : h5py.Group
    names : list of str
        The datasets, created (if still waiting) in this order on close.
    """

    def __init__(self, group, names):
        self.group, self.names = group, list(names)
        self.waiting = {name: [] for name in self.names}
        self.counts = dict.fromkeys(self.names, 0)

    def rows(self, name):
        """Rows appended so far to ``name`` (written or waiting): int."""
        return self.counts[name]

    def append(self, name, values):
        """Append the rows ``values`` (array; its trailing shape and dtype kind those of
        every other append to ``name``)."""
        values = np.asarray(values)
        self.waiting[name].append(values)
        self.counts[name] += len(values)
        if sum(v.nbytes for v in self.waiting[name]) >= APPEND_BYTES:
            self._flush(name)

    def _joined(self, name):
        parts = self.waiting[name]
        self.waiting[name] = []
        filled = [p for p in parts if len(p)]  # (an empty part may carry another dtype)
        return np.concatenate(filled) if filled else (parts[0] if parts else np.zeros(0))

    def _flush(self, name):
        data = self._joined(name)
        if name not in self.group:
            kwargs = {"track_times": False, "maxshape": (None, *data.shape[1:]), "chunks": _row_chunks(data)}
            coder = COMPRESSIONS[_compression.get()]
            if coder:
                kwargs.update(compression=coder[0], compression_opts=coder[1], shuffle=data.dtype.kind != "f")
            self.group.create_dataset(name, data=data, **kwargs)
            return
        dset = self.group[name]
        n = len(dset)
        dset.resize(n + len(data), axis=0)
        dset[n:] = data

    def close(self):
        """Write every waiting row."""
        for name in self.names:
            if name in self.group:
                if self.waiting[name]:
                    self._flush(name)
            else:
                write_dataset(self.group, name, self._joined(name))


_NODE_ARRAYS = ["kind", "generators", "direction", "ends", "blocker_kind", "blocker", "generator_points"]


def write_nodes(group, nodes):
    """Fill a ``V0`` group with :class:`viscx.skeleton.nodes.Nodes` (see docs/format.md)."""
    for name in _NODE_ARRAYS:
        write_dataset(group, name, getattr(nodes, name))
    group.attrs["kinds"] = json.dumps({"E4": 0, "VEE": 1, "VV": 2})
    group.attrs["blocker_kinds"] = json.dumps({"face": 0, "sky": 1, "edge": 2, "vertex": 3})


def read_nodes(group):
    """The :class:`viscx.skeleton.nodes.Nodes` stored in a ``V0`` group (checked:
    :func:`viscx.formats.validate.node_arrays`)."""
    from viscx.skeleton.nodes import Nodes

    return Nodes(**validate.node_arrays(group, group.file.filename, validate.scene_sizes(group.file)))


def stored_nodes(group):
    """The :class:`viscx.skeleton.nodes.Nodes` of a ``V0`` group left in the file: each
    field the group's h5py dataset, read by rows as it is sliced. What a streamed V1 reads
    of the V0 it has just written (:func:`viscx.pipeline.stream_arcs`: chunks of nodes),
    so that the whole level is never in memory again; not checked (the build's own file)."""
    from viscx.skeleton.nodes import Nodes

    return Nodes(**{name: group[name] for name in Nodes.__dataclass_fields__})


_ARC_ARRAYS = [
    "kind",
    "generators",
    "interval",
    "end_type",
    "end_node",
    "blocker_kind",
    "blocker",
    "parameter",
    "direction",
    "ends",
    "generator_points",
]
_HALF_CELL_ARRAYS = ["arc", "vertex", "edge", "up_kind", "up", "down_kind", "down", "start", "end", "start_type", "end_type"]


def write_arcs(group, arcs):
    """Fill a ``V1`` group with :class:`viscx.skeleton.arcs.Arcs` (see docs/format.md):
    the arcs, ``planar/`` (the planar E4 events arcs end at, laid out like ``/V0``) and
    ``half_cells/`` (one VE half-cell per VE arc)."""
    from viscx.skeleton.arcs import XE

    for name in _ARC_ARRAYS:
        write_dataset(group, name, getattr(arcs, name))
    _arc_attributes(group, np.any(arcs.kind == XE))
    write_nodes(group.create_group("planar", track_order=True), arcs.planar)
    hc = group.create_group("half_cells", track_order=True)
    for name in _HALF_CELL_ARRAYS:
        write_dataset(hc, name, getattr(arcs.half_cells, name))


def _arc_attributes(group, has_xe):
    """The code tables of a ``V1`` group (``kinds`` lists XE only when it has XE arcs:
    other files stay as they were)."""
    from viscx.skeleton.arcs import END_NAMES, KIND_NAMES, XE

    group.attrs["kinds"] = json.dumps({v: k for k, v in KIND_NAMES.items() if k != XE or has_xe})
    group.attrs["end_types"] = json.dumps({v: k for k, v in END_NAMES.items()})
    group.attrs["blocker_kinds"] = json.dumps({"face": 0, "sky": 1, "edge": 2, "vertex": 3})


class ArcsAppender:
    """Arcs (V1) written chunk by chunk into their group, as :func:`write_arcs` writes them
    whole: each chunk's arcs after the previous chunks', its half-cells' arc ids shifted
    by the arcs already written; the planar events (built before the arcs, whole) and the
    code tables on :meth:`close`.

    Parameters
    ----------
    group : h5py.Group
        ``V1``.
    """

    def __init__(self, group):
        self.group = group
        self.arcs = Appender(group, _ARC_ARRAYS)
        self.half_cells = Appender(group.create_group("half_cells", track_order=True), _HALF_CELL_ARRAYS)
        self.has_xe = False

    def __len__(self):
        return self.arcs.rows("kind")

    def append(self, arcs, half_cells=None):
        """Append a chunk's arcs (a dict of the per-arc arrays of :class:`Arcs`) and their
        half-cells (HalfCells, arc ids the chunk's; None for none)."""
        from viscx.skeleton.arcs import XE

        shift = len(self)
        for name in _ARC_ARRAYS:
            self.arcs.append(name, arcs[name])
        self.has_xe |= bool(np.any(arcs["kind"] == XE))
        if half_cells is not None:
            for name in _HALF_CELL_ARRAYS:
                values = getattr(half_cells, name)
                self.half_cells.append(name, values + shift if name == "arc" else values)

    def close(self, planar):
        """Write everything waiting, the code tables and the planar events ``planar`` (Nodes)."""
        self.arcs.close()
        self.half_cells.close()
        _arc_attributes(self.group, self.has_xe)
        write_nodes(self.group.create_group("planar", track_order=True), planar)


def read_arcs(group):
    """The :class:`viscx.skeleton.arcs.Arcs` stored in a ``V1`` group (checked:
    :func:`viscx.formats.validate.arc_arrays`)."""
    from viscx.skeleton.arcs import Arcs, HalfCells
    from viscx.skeleton.nodes import Nodes

    arrays, planar, half = validate.arc_arrays(group, group.file.filename, validate.scene_sizes(group.file))
    return Arcs(**arrays, planar=Nodes(**planar), half_cells=HalfCells(**half))


_VCELL_ARRAYS = ["vertex", "up_kind", "up", "down_kind", "down", "solid_angle", "twin", "complete", "loop_offsets", "turning",
                 "element_offsets", "element", "antipodal"]
# open chains live in V2/open/ under their names without the prefix
_OPEN_ARRAYS = ["offsets", "element", "antipodal", "vertex", "up_kind", "up", "down_kind", "down"]


def write_vcells(group, vcells):
    """Fill a ``V2`` group with :class:`viscx.skeleton.vcells.VCells` (see docs/format.md):
    the cells with their boundary loops as CSR lists, and ``open/`` (chains that did
    not close)."""
    _write_cells(group, vcells, _VCELL_ARRAYS, _OPEN_ARRAYS, {"face": 0, "sky": 1, "vertex": 3})


def _write_cells(group, cells, arrays, open_arrays, blocker_kinds):
    """The 2-cells' arrays, blocker kinds and counts into ``group``, their open chains
    into ``group/open`` (named without the ``open_`` prefix)."""
    for name in arrays:
        write_dataset(group, name, getattr(cells, name))
    group.attrs["blocker_kinds"] = json.dumps(blocker_kinds)
    group.attrs["counts"] = json.dumps(cells.counts())
    chains = group.create_group("open", track_order=True)
    for name in open_arrays:
        write_dataset(chains, name, getattr(cells, f"open_{name}"))


def read_vcells(group):
    """The :class:`viscx.skeleton.vcells.VCells` stored in a ``V2`` group (checked:
    :func:`viscx.formats.validate.vcell_arrays`)."""
    from viscx.skeleton.vcells import VCells

    return VCells(**validate.vcell_arrays(group, group.file.filename, validate.scene_sizes(group.file)))


_EECELL_ARRAYS = ["edge1", "edge2", "back_kind", "back", "front_kind", "front", "area", "complete", "loop_offsets",
                  "turning", "element_offsets", "element", "element_kind", "element_interval"]
# open chains live in V2/ee/open/ under their names without the prefix
_EE_OPEN_ARRAYS = ["offsets", "element", "element_kind", "interval", "edge1", "edge2", "back_kind", "back", "front_kind",
                   "front"]


def write_eecells(group, eecells):
    """Fill ``V2/ee`` with :class:`viscx.skeleton.eecells.EECells` (see docs/format.md):
    the cells with their boundary loops as CSR lists of signed arc ids, and ``open/``."""
    from viscx.skeleton.eecells import ARC, PENCIL1, PENCIL2, SIDE

    ee = group.create_group("ee", track_order=True)
    _write_cells(ee, eecells, _EECELL_ARRAYS, _EE_OPEN_ARRAYS, {"face": 0, "sky": 1, "edge": 2})
    ee.attrs["element_kinds"] = json.dumps({"arc": ARC, "side": SIDE, "pencil1": PENCIL1, "pencil2": PENCIL2})
    # the level's counts (what `viscx info` prints) gain the EE-cells'
    counts = json.loads(group.attrs.get("counts", "{}"))
    counts.update({f"ee_{k}": v for k, v in eecells.counts().items()})
    group.attrs["counts"] = json.dumps(counts)


def read_eecells(group):
    """The :class:`viscx.skeleton.eecells.EECells` stored in a ``V2`` group (checked:
    :func:`viscx.formats.validate.eecell_arrays`)."""
    from viscx.skeleton.eecells import EECells

    if "ee" not in group:
        raise ViscxError("this file has no EE-cells (V2/ee); rebuild it with `viscx build --levels 2`")
    return EECells(**validate.eecell_arrays(group["ee"], group.file.filename, validate.scene_sizes(group.file)))


# the CSR offsets and cell references of the 2-cells' arrays, each shifted by the rows
# of the array it points into already written when a chunk is appended
_VCELL_SHIFTS = {"twin": "vertex", "loop_offsets": "turning", "element_offsets": "element"}
_EECELL_SHIFTS = {"loop_offsets": "turning", "element_offsets": "element"}
_OPEN_SHIFTS = {"offsets": "element"}
# the open chains' arrays with one row per element (the others: one per chain)
_OPEN_ELEMENT_ARRAYS = {"element", "antipodal", "element_kind", "interval"}


class CellsAppender:
    """2-cells (V-cells, or EE-cells) written chunk by chunk into their group, as
    :func:`write_vcells` / :func:`write_eecells` write them whole: each chunk's cells, loops
    and elements after the previous chunks', their CSR offsets and cell ids (``twin``)
    shifted by what is already written, the open chains likewise, and the ``counts``
    attribute summed over the chunks (chunks of whole vertices, or whole edge pairs, so
    that every count adds up). Chains may be held back (:meth:`hold_chains`) to be written
    after every chunk's others, the order :func:`viscx.skeleton.eecells._concatenate_cells`
    gives them.

    Parameters
    ----------
    group : h5py.Group
        ``V2`` for V-cells; for EE-cells ``V2``, whose ``ee`` group is made here.
    ee : bool
        EE-cells.
    """

    def __init__(self, group, ee=False):
        from viscx.skeleton.eecells import ARC, PENCIL1, PENCIL2, SIDE

        self.parent, self.ee = group, ee
        if ee:
            group = group.create_group("ee", track_order=True)
            group.attrs["element_kinds"] = json.dumps({"arc": ARC, "side": SIDE, "pencil1": PENCIL1, "pencil2": PENCIL2})
        self.group = group
        arrays, self.open_names = (_EECELL_ARRAYS, _EE_OPEN_ARRAYS) if ee else (_VCELL_ARRAYS, _OPEN_ARRAYS)
        self.shifts = _EECELL_SHIFTS if ee else _VCELL_SHIFTS
        group.attrs["blocker_kinds"] = json.dumps({"face": 0, "sky": 1, "edge": 2} if ee else {"face": 0, "sky": 1, "vertex": 3})
        self.cells = Appender(group, arrays)
        self.chains = Appender(group.create_group("open", track_order=True), self.open_names)
        for app, shifts in ((self.cells, self.shifts), (self.chains, _OPEN_SHIFTS)):
            for name in shifts:
                if name.endswith("offsets"):
                    app.append(name, np.zeros(1, np.int64))
        self.counts, self.held = {}, []

    def append(self, cells, chains=None):
        """Append a chunk's cells (VCells or EECells) and its open chains ``chains`` (a
        slice of them; default all)."""
        for name, value in cells.counts().items():
            self.counts[name] = self.counts.get(name, 0) + value
        _append_shifted(self.cells, {name: getattr(cells, name) for name in self.cells.names}, self.shifts)
        self._append_chains(cells, chains if chains is not None else slice(0, len(cells.open_offsets) - 1))

    def hold_chains(self, cells, chains):
        """Keep the open chains ``chains`` (a slice) of a chunk appended before, to be
        written on :meth:`close` after every chunk's other chains."""
        self.held.append(_chain_slice(cells, self.open_names, chains))

    def _append_chains(self, cells, chains):
        _append_shifted(self.chains, _chain_slice(cells, self.open_names, chains), _OPEN_SHIFTS)

    def close(self):
        """Write the held chains, everything waiting and the counts."""
        for arrays in self.held:
            _append_shifted(self.chains, arrays, _OPEN_SHIFTS)
        self.held = []
        self.cells.close()
        self.chains.close()
        self.group.attrs["counts"] = json.dumps(self.counts)
        if self.ee:  # the level's counts (what `viscx info` prints) gain the EE-cells'
            counts = json.loads(self.parent.attrs.get("counts", "{}"))
            counts.update({f"ee_{k}": v for k, v in self.counts.items()})
            self.parent.attrs["counts"] = json.dumps(counts)


def _chain_slice(cells, names, chains):
    """``{name: values}`` of the open chains ``chains`` (a slice) of 2-cells: their
    offsets from 0, their elements' arrays and their own."""
    offsets = cells.open_offsets[chains.start: chains.stop + 1]
    elements = slice(int(offsets[0]), int(offsets[-1]))
    out = {}
    for name in names:
        if name == "offsets":
            out[name] = offsets - offsets[0]
        else:
            out[name] = getattr(cells, f"open_{name}")[elements if name in _OPEN_ELEMENT_ARRAYS else chains]
    return out


def _append_shifted(app, arrays, shifts):
    """Append a chunk's ``arrays`` ({name: values}) to ``app``; the names in ``shifts``
    (name: the dataset it points into) shifted by that dataset's rows before this chunk:
    CSR offsets lose their leading 0, ids (>= 0) are moved."""
    base = {name: app.rows(into) for name, into in shifts.items()}
    for name, values in arrays.items():
        if name in base:
            values = values[1:] + base[name] if name.endswith("offsets") else np.where(values >= 0, values + base[name], values)
        app.append(name, values)


class ViscxFile:
    """An open, validated viscx file (use as a context manager).

    Raises :class:`ViscxError` for a missing file, a file that is not HDF5
    (or is truncated), an HDF5 file from another program, or a file written by
    a newer format version.
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.exists():
            raise ViscxError(f"no such file: {self.path}")
        if self.path.is_dir():
            raise ViscxError(f"{self.path} is a directory, not a viscx file")
        register_input(self.path)
        try:
            self.h5 = h5py.File(self.path, "r")
        except OSError:
            raise ViscxError(f"{self.path} is not a readable HDF5 file (corrupt, truncated or another format)") from None
        attrs = self.h5.attrs
        if attrs.get("format") != FORMAT:
            self.h5.close()
            raise ViscxError(f"{self.path} is an HDF5 file but not one written by viscx")
        try:
            version = int(attrs.get("format_version", -1))
        except (TypeError, ValueError):
            version = attrs.get("format_version")
            self.h5.close()
            raise ViscxError(f"{self.path} is a damaged viscx file (format_version {version!r} is not a number)") from None
        if version > FORMAT_VERSION:
            self.h5.close()
            raise ViscxError(
                f"{self.path} has format version {version}, newer than this viscx reads ({FORMAT_VERSION}); upgrade viscx"
            )
        if version < 1 or "scene" not in self.h5:
            self.h5.close()
            raise ViscxError(f"{self.path} is a damaged viscx file (no scene level)")
        missing = [name for name in _REQUIRED_ATTRS if name not in attrs]
        if missing:
            self.h5.close()
            raise ViscxError(f"{self.path} is a damaged viscx file (missing attribute {missing[0]!r})")
        try:  # nothing is read before the file's structure is known to be safe
            validate.check_structure(self.h5, self.path)
            validate.check_attributes(self.h5, self.path)
        except BaseException:
            self.h5.close()
            raise

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.h5.close()

    @property
    def levels(self):
        return json.loads(self.h5.attrs["levels"])

    @property
    def options(self):
        return json.loads(self.h5.attrs["options"])

    @property
    def timings(self):
        if "provenance" not in self.h5 or "timings" not in self.h5["provenance"].attrs:
            return {}
        return validate.load_json(self.h5["provenance"].attrs["timings"], f"{self.path}: attribute /provenance@timings")

    def read_scene(self):
        """The :class:`Scene` stored in the file."""
        arrays, he, edges, names, materials = validate.scene_arrays(self.h5["scene"], self.path)
        half_edges = HalfEdges(**he, **edges)
        attrs = self.h5.attrs
        return Scene(
            **arrays,
            group_names=names,
            material_names=materials,
            half_edges=half_edges,
            weld_tolerance=float(attrs["weld_tolerance"]),
            epsilon=float(attrs["epsilon"]),
            source=str(attrs.get("scene_name", "")),
            sha256=str(attrs.get("scene_sha256", "")),
        )


def _read_points(self):
    """(k, 3) float64: the free points stored by ``viscx build --point`` (generator
    vertices ``n_vertices + i``); empty when there are none."""
    return validate.points_array(self.h5["scene"], self.path)


ViscxFile.read_points = _read_points


def read_scene(path):
    """The :class:`Scene` stored in a viscx file."""
    with ViscxFile(path) as f:
        return f.read_scene()
