"""V2 in independent chunks: the V-cells of ranges of vertices, the EE-cells of chunks of squares.

A V-cell lies on one vertex's sphere and an EE-cell in one edge pair's square: the
cells of disjoint sets of vertices (of squares) are built from disjoint sets of boundary
elements and never meet. The builders order every output by vertex (by edge pair)
first and, within it, by rules that only compare elements of that vertex (square), so
the chunks' cells, each chunk's ids shifted, concatenate to exactly what one call
over the whole scene gives (:func:`viscx.skeleton.vcells.build_vcells`,
:func:`viscx.skeleton.eecells.build_eecells`; tests/test_distributed.py checks it).
Chunks are what a process works on at a time and what a distributed build sends to
its workers (:mod:`viscx.distributed`); :class:`viscx.formats.hdf5.CellsAppender`
writes them as they come.
"""

from dataclasses import replace

import numpy as np

from viscx.skeleton.arcs import Arcs, HalfCells
from viscx.skeleton.eecells import ARC, squares_cells, square_chunks
from viscx.skeleton.vcells import build_vcells

#: Half-cells (VE arcs) per chunk of vertices of :func:`vcell_parts`, and arc-square
#: incidences per chunk of squares of :func:`eecell_parts`: a chunk's boundary elements
#: and loops are what a streamed V2 holds (random_boxes(301), one process: V2's peak
#: 1.17 GB in chunks of 2^18 and 2^20, one chunk each, 0.76 GB in chunks of 2^15 and
#: 2^17, as V1's 0.59 GB; CPU 32.2 -> 34.6 s, the machine shared).
VCELL_CHUNK = 1 << 15
EECELL_CHUNK = 1 << 17

# the per-arc arrays of Arcs
_ARC_ARRAYS = ("kind", "generators", "interval", "end_type", "end_node", "blocker_kind", "blocker", "parameter", "direction",
               "ends", "generator_points")


#: What V2 reads of the arcs (besides their half-cells and planar events): V-cells the
#: VE arcs' generators, intervals and sample parameters, EE-cells every arc's kind,
#: generators and interval (about 50 of the 230 bytes of an arc).
V2_ARC_ARRAYS = ("kind", "generators", "interval", "parameter")


def v2_arcs(arcs, ids=slice(None), half_rows=slice(None)):
    """The arcs ``ids`` (default all; else (k,) int, ascending) with only what V2 reads
    (V2_ARC_ARRAYS; the other per-arc arrays and the planar events empty), arc i of them
    being ``ids[i]``, their half-cells the rows ``half_rows`` of ``arcs.half_cells`` (whose
    arcs must be among ``ids``, renumbered so). What a streamed build keeps of V1 once it
    is written, and what a chunk's task gets of it. Ids ascend, so every order of arc ids
    the builders use is the same in the subset. ``arcs`` may be :func:`stored_v2_arcs`'s,
    read from the file: only the rows asked for are read (for ``ids``, those from the
    first to the last)."""
    hc = arcs.half_cells
    half = {name: getattr(hc, name)[half_rows] for name in HalfCells.__dataclass_fields__}
    if not isinstance(ids, slice):
        half["arc"] = np.searchsorted(ids, half["arc"])
    planar = arcs.planar
    return Arcs(**{name: _rows(getattr(arcs, name), ids) if name in V2_ARC_ARRAYS else getattr(arcs, name)[:0]
                   for name in _ARC_ARRAYS},
                planar=type(planar)(**{name: getattr(planar, name)[:0] for name in planar.__dataclass_fields__}),
                half_cells=HalfCells(**half))


def _rows(values, ids):
    """``values[ids]`` (``ids`` a slice or (k,) int, ascending) of an array or of an h5py
    dataset, which then reads only its rows ``ids[0]`` to ``ids[-1]``: the arcs of a chunk
    of V-cells are a run of consecutive VE arcs (VE arcs are sorted by vertex)."""
    if isinstance(ids, slice):
        return values[ids]
    if not len(ids):
        return values[:0]
    lo = int(ids[0])
    return values[lo: int(ids[-1]) + 1][ids - lo]


def stored_v2_arcs(group):
    """What V2 reads of the arcs stored in a ``V1`` group (of a file being written too),
    read on demand: arcs whose V2_ARC_ARRAYS and half-cells are the group's datasets
    (h5py; the other arrays and the planar events empty), to be read through
    :func:`v2_arcs` and :func:`vcell_parts` only, while the file is open. The V-cells'
    chunks read their own rows of the half-cells and arcs (:func:`vcell_parts`), so the
    half-cells (78 bytes each) are never in memory all at once; the EE-cells read every
    arc's V2_ARC_ARRAYS once (:func:`viscx.pipeline.stream_two_cells`)."""
    from viscx.skeleton.nodes import Nodes

    planar = group["planar"]
    return Arcs(**{name: group[name] if name in V2_ARC_ARRAYS else group[name][:0] for name in _ARC_ARRAYS},
                planar=Nodes(**{name: planar[name][:0] for name in Nodes.__dataclass_fields__}),
                half_cells=HalfCells(**{name: group["half_cells"][name] for name in HalfCells.__dataclass_fields__}))


def vcell_parts(scene, arcs, size=None):
    """The V-cells' chunks: consecutive ranges of generator vertices holding about
    ``size`` (default VCELL_CHUNK) half-cells each (a vertex's half-cells never split; one
    chunk at least), each as the arguments of :func:`vcells_of_part` after the scene,
    made one at a time. From :func:`stored_v2_arcs`, each chunk reads its own rows of the
    file.

    Yields
    ------
    part : Arcs
        The VE arcs of the chunk's vertices (:func:`v2_arcs`), with their half-cells.
    vertices : (v,) int
        The chunk's generator vertices.
    shift : int
        The first half-cell of the chunk (its half-cell 0 in the whole build).
    """
    size = size or VCELL_CHUNK
    hc = arcs.half_cells
    vertex = hc.vertex[()]  # (read whole from a file: 8 bytes a half-cell)
    generators = scene.generator_vertices
    if np.any(np.diff(vertex) < 0):  # (not built by build_arcs, e.g. points merged in): one chunk
        yield v2_arcs(arcs), None, 0
        return
    n = max(scene.n_vertices, int(vertex[-1]) + 1 if len(vertex) else 0, 1)
    # the first half-cell of every vertex 0..n, and cuts at the vertex holding every size-th one
    first = np.searchsorted(vertex, np.arange(n + 1))
    cuts = np.searchsorted(first, np.arange(size, len(vertex), size), "right") - 1
    bounds = np.unique(np.r_[0, cuts[cuts > 0], n])
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        rows = slice(int(first[lo]), int(first[hi]))
        yield (v2_arcs(arcs, hc.arc[rows], rows), generators[(generators >= lo) & (generators < hi)], rows.start)


def vcells_of_part(scene, part, vertices, shift):
    """The V-cells of a chunk of :func:`vcell_parts`, their half-cell ids the whole build's.

    Returns
    -------
    VCells
    """
    cells = build_vcells(scene, part, vertices=vertices)
    # signed half-cell ids ±(h + 1), h the chunk's: the whole build's h is shift more
    return replace(cells, element=cells.element + np.sign(cells.element) * shift,
                   open_element=cells.open_element + np.sign(cells.open_element) * shift)


def eecell_parts(scene, arcs, size=None):
    """The EE-cells' chunks (:func:`viscx.skeleton.eecells.square_chunks`: about ``size``
    (default EECELL_CHUNK) arc-square incidences, every square whole), each as the arguments of
    :func:`eecells_of_part` after the scene, made one at a time. The arcs' rows go along
    with their incidences through the squares' spill: from :func:`stored_v2_arcs`, the
    file is read a slice of arcs at a time, and no part of V1 is held whole.

    Yields
    ------
    part : Arcs
        The arcs bounding the chunk's squares (:func:`v2_arcs`, without half-cells).
    squares : ((k,) int, (k,) int, (k,) int)
        The chunk's (arc, e1, e2) incidences, arcs numbered in ``part``.
    ids : (a,) int
        Arc i of ``part`` is arc ``ids[i]`` of the whole build.
    """
    none = v2_arcs(arcs, np.zeros(0, np.int64), slice(0, 0))
    for arc, e1, e2, *rows in square_chunks(scene, arcs, size or EECELL_CHUNK, carry=V2_ARC_ARRAYS):
        ids, first = np.unique(arc, return_index=True)
        part = replace(none, **{name: values[first] for name, values in zip(V2_ARC_ARRAYS, rows)})
        yield part, (np.searchsorted(ids, arc), e1, e2), ids


def eecells_of_part(scene, part, squares, ids):
    """The EE-cells of a chunk of :func:`eecell_parts`, their arc ids the whole build's,
    and how many of its open chains (listed first) are demoted loops: the whole build lists
    every chunk's before the others (:func:`viscx.skeleton.eecells._concatenate_cells`).

    Returns
    -------
    (EECells, int)
    """
    cells, demoted = squares_cells(scene, part, squares)

    def whole(element, kind):
        """Signed arc ids ±(a + 1) of the chunk's arcs as the whole build's (other kinds kept)."""
        arc = kind == ARC
        out = element.copy()
        out[arc] = np.sign(element[arc]) * (ids[np.abs(element[arc]) - 1] + 1)
        return out

    return replace(cells, element=whole(cells.element, cells.element_kind),
                   open_element=whole(cells.open_element, cells.open_element_kind)), demoted
