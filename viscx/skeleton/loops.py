"""The loop engine of the 2-cells, shared by the V-cells (a vertex's direction sphere,
:mod:`viscx.skeleton.vcells`) and the EE-cells (an edge pair's square,
:mod:`viscx.skeleton.eecells`): Hoberock et al.'s FormLoops (§5.3) chains boundary
elements end to start into loops, turning sums measure them, and loops of one group
are grouped into cells by ray-crossing parity (§5.4).

Elements are anything with ``start``, ``end``, ``start_tangent`` and ``end_tangent``
((k, 3) float); signed angles are taken about ``end`` (the sphere's normal there; the
EE-cells embed their square as the plane z = 1).
"""

import numpy as np
from numba import njit

from viscx.arrays import row_norms, unique_rows, walk_cycle

#: Decimals to which turning sums are compared when choosing a cell's outer loop.
TURNING_DECIMALS = 9


def signed_angle(a, b, normal):
    """Angle from a to b about normal (counter-clockwise positive), in (-π, π]."""
    return np.arctan2(np.einsum("ij,ij->i", np.cross(a, b), normal), np.einsum("ij,ij->i", a, b))


def loop_successors(loop_offsets):
    """The next element of each element of the loops (elements of loop j contiguous:
    ``loop_offsets[j]:loop_offsets[j + 1]``, the last one followed by the first).

    Returns
    -------
    nxt : (n,) int
    loop_of : (n,) int
        The loop of each element.
    """
    n = loop_offsets[-1]
    loop_of = np.repeat(np.arange(len(loop_offsets) - 1), np.diff(loop_offsets))
    nxt = np.arange(1, n + 1)
    nxt[loop_offsets[1:] - 1] = loop_offsets[:-1]
    return nxt, loop_of


def corner_turns(el, loop_offsets):
    """(n,) float: the signed turning angle (left turns positive) at the end of each element
    of the loops, from its end tangent to the next element's start tangent, about its end."""
    n = loop_offsets[-1]
    nxt, _ = loop_successors(loop_offsets)
    return signed_angle(el.end_tangent[:n], el.start_tangent[nxt], el.end[:n])


def turning_sums(el, loop_offsets):
    """Sum of the signed turning angles (left turns positive) at the corners of each loop.

    Returns
    -------
    (l,) float
        On the unit sphere, 2π minus the solid angle of the loop's left region
        (Gauss-Bonnet; :func:`viscx.skeleton.vcells.sphere_turning_sums` bridges the gaps
        of joined chains).
    """
    _, loop_of = loop_successors(loop_offsets)
    return np.bincount(loop_of, weights=corner_turns(el, loop_offsets), minlength=len(loop_offsets) - 1)


def pairs_in_groups(group):
    """All ordered pairs (i, j), i and j in one group (i = j included).

    Parameters
    ----------
    group : (n,) int

    Returns
    -------
    i, j : (m,) int
    """
    order = np.argsort(group, kind="stable")
    _, first, size = np.unique(group[order], return_index=True, return_counts=True)
    rep = np.repeat(size, size)  # per element (sorted): its group's size
    start = np.repeat(first, size)
    i = np.repeat(np.arange(len(group)), rep)
    j = np.repeat(start, rep) + np.arange(rep.sum()) - np.repeat(np.cumsum(rep) - rep, rep)
    return order[i], order[j]


def near_pairs(a, b, group, tolerance):
    """All pairs (i, j) with group[i] == group[j] and |a[i] - b[j]| <= tolerance[i]: the
    pairs of :func:`pairs_in_groups` that pass that test, found output-sensitively.

    Points are binned by (group, x, y) in square cells at least twice the largest
    tolerance wide (2^15 across at most, so the keys fit an int64); each a[i] takes
    the b of the 3 × 3 cells around its own, and the exact test filters them.

    Parameters
    ----------
    a, b : (n, 3) float
    group : (n,) int
    tolerance : float or (n,) float

    Returns
    -------
    i, j : (m,) int
        Sorted by (i, j).
    """
    n = len(a)
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (n,))
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    lo = np.minimum(a[:, :2].min(axis=0), b[:, :2].min(axis=0))
    extent = float(np.max(np.maximum(a[:, :2].max(axis=0), b[:, :2].max(axis=0)) - lo))
    width = max(2 * float(tolerance.max()), extent / 2**15, 1e-300)
    cell_a = np.floor((a[:, :2] - lo) / width).astype(np.int64) + 1
    cell_b = np.floor((b[:, :2] - lo) / width).astype(np.int64) + 1
    m = int(max(cell_a.max(), cell_b.max())) + 2
    _, g = np.unique(group, return_inverse=True)
    g = g.reshape(-1).astype(np.int64)
    key_b = (g * m + cell_b[:, 0]) * m + cell_b[:, 1]
    order = np.argsort(key_b, kind="stable")
    key_a = (g * m + cell_a[:, 0]) * m + cell_a[:, 1]
    # the a's by their own cell's key: each neighbour's key is that plus a constant, so the
    # nine runs of b are found by pointers that only move forward
    by_a = np.argsort(key_a, kind="stable")
    i, j = _near_in_cells(key_a, by_a, key_b[order], order, m, np.ascontiguousarray(a, dtype=np.float64),
                          np.ascontiguousarray(b, dtype=np.float64), np.ascontiguousarray(tolerance))
    pick = np.lexsort([j, i])
    return i[pick], j[pick]


@njit(cache=True, nogil=True)
def _near_in_cells(key_a, by_a, sorted_keys, order, m, a, b, tolerance):
    """The pairs of :func:`near_pairs` in any order: each a[i] (in the order ``by_a`` of its
    key) against the b of the 3 × 3 cells around its own (the run of each neighbour's key
    in ``sorted_keys``, b's keys sorted, ``order`` their rows), kept where the distance,
    summed as :func:`viscx.arrays.row_norms` sums it, is within ``tolerance[i]``."""
    out_i = np.empty(max(16, 4 * len(key_a)), np.int64)
    out_j = np.empty_like(out_i)
    n_out = 0
    nb = len(sorted_keys)
    lo = np.zeros(9, np.int64)
    hi = np.zeros(9, np.int64)
    for r in range(len(by_a)):
        i = by_a[r]
        for q in range(9):
            key = key_a[i] + ((q // 3 - 1) * m + (q % 3 - 1))
            while lo[q] < nb and sorted_keys[lo[q]] < key:
                lo[q] += 1
            hi[q] = max(hi[q], lo[q])
            while hi[q] < nb and sorted_keys[hi[q]] <= key:
                hi[q] += 1
            for k in range(lo[q], hi[q]):
                j = order[k]
                s = 0.0
                for c in range(a.shape[1]):
                    d = a[i, c] - b[j, c]
                    s += d * d
                if np.sqrt(s) <= tolerance[i]:
                    if n_out == len(out_i):
                        out_i = np.concatenate((out_i, np.empty_like(out_i)))
                        out_j = np.concatenate((out_j, np.empty_like(out_j)))
                    out_i[n_out] = i
                    out_j[n_out] = j
                    n_out += 1
    return out_i[:n_out], out_j[:n_out]


def unique_elements(el, group, tolerance, same_curve=None):
    """The elements to keep: of elements of one group running between the same two points
    (and one curve by the test ``same_curve``, if given), each within ``tolerance`` of the first one's,
    the first (smallest index).

    Two families whose lines coincide give the same boundary twice: collinear edges
    overlapping (two boxes' bottom edges along their contact), a vertex and two edges in
    one plane (a line through v meets both), two pencils of one plane through one point
    (an edge pair's square, docs/skeleton.md "Furnished buildings"). FormLoops would take
    one of the two and leave the other dangling as an open chain. In general position no
    two elements coincide.

    Parameters
    ----------
    el : Elements
        Anything with ``start``, ``end`` ((k, 3) float).
    group : (k,) int
    tolerance : float or (k,) float
    same_curve : callable, optional
        ``same_curve(i, j)`` ((m,) int each, i < j) -> (m,) bool: whether elements i and j, whose
        ends agree, are one curve. On the sphere the ends fix an arc shorter than pi; in an
        edge pair's square they do not fix the curve.

    Returns
    -------
    (k,) int
        Increasing element indices.
    """
    if len(el) == 0:
        return np.zeros(0, np.int64)
    tolerance = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (len(el),))
    i, j = near_pairs(el.start, el.start, group, tolerance)
    later = j > i
    i, j = i[later], j[later]
    same = row_norms(np.take(el.end, i, axis=0) - np.take(el.end, j, axis=0)) <= np.take(tolerance, i)
    i, j = i[same], j[same]
    if same_curve is not None and len(i):
        keep = same_curve(i, j)
        i, j = i[keep], j[keep]
    drop = np.zeros(len(el), bool)
    drop[j] = True
    return np.flatnonzero(~drop)


def chain_extents(walk, chain_offsets):
    """How far each chain reaches: the largest distance of an end of its elements from the
    chain's start ((o,) float; chain j is ``walk[chain_offsets[j]:chain_offsets[j + 1]]``,
    ``start`` and ``end`` (k, 3) float). A chain within the join tolerance is a point at
    epsilon's resolution (the V-cells' and the EE-cells' ``point_chains``)."""
    n = len(chain_offsets) - 1
    if n == 0:
        return np.zeros(0)
    first = chain_offsets[:-1]
    k = np.arange(chain_offsets[0], chain_offsets[-1])
    chain_of = np.repeat(np.arange(n), np.diff(chain_offsets))
    origin = walk.start[first][chain_of]
    far = np.maximum(row_norms(walk.start[k] - origin), row_norms(walk.end[k] - origin))
    extent = np.zeros(n)
    np.maximum.at(extent, chain_of, far)
    return extent


def form_loops(el, group, tolerance, near=None):
    """Chain each group's elements end to start into loops (Hoberock et al. §5.3 FormLoops).

    Candidates to follow an element are the elements of its group starting
    within ``tolerance`` of its end; the first clockwise from the reversed
    incoming tangent wins, exact ties to the smaller id, each element followed
    at most once. Elements that cannot lie on a loop (no candidate before or
    after them, repeatedly) choose last; with ``near``, so do links whose start lies
    farther than ``near`` from the end (a start at the same event, only rounding apart,
    before one a merged event away, whatever their angles).

    Parameters
    ----------
    el : Elements
        Anything with ``start``, ``end``, ``start_tangent``, ``end_tangent`` ((k, 3)
        float; signed angles are taken about ``end``: EE-cells embed their square as
        the plane z = 1).
    group : (k,) int
    tolerance : float or (k,) float
        Per element: how far its end may be from a start it is joined to.
    near : float or (k,) float, optional
        Per element: the distance within which a start is the same point as its end.

    Returns
    -------
    order : (k,) int
        The elements walk by walk: the closed loops (each from its smallest
        element), then the open chains.
    loop_offsets : (l + 1,) int
        Loop j is ``order[loop_offsets[j]:loop_offsets[j + 1]]``.
    chain_offsets : (o + 1,) int
        Open chain j is ``order[chain_offsets[j]:chain_offsets[j + 1]]``.
    """
    if len(el) == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64)
    i, j = near_pairs(el.end, el.start, group, tolerance)
    cw = np.mod(-signed_angle(-el.end_tangent[i], el.start_tangent[j], el.end[i]), 2 * np.pi)
    cw = np.where(cw <= 1e-12, 2 * np.pi, cw)  # going straight back is the last choice
    closable = _closable_links(len(el), i, j)
    far = np.zeros(len(i), bool)
    if near is not None:
        far = row_norms(el.end[i] - el.start[j]) > np.broadcast_to(near, (len(el),))[i]
    pick = np.lexsort([j, i, cw, far, ~closable])
    return _trace(_greedy_match(len(el), i[pick], j[pick]))


def _closable_links(n, i, j):
    """Links between elements that may lie on a loop: elements without a candidate before
    or after them (dangling ends, e.g. a VE arc ending at a transition nothing else meets)
    are set aside, repeatedly, so that they cannot take a closing element's successor.

    The elements kept are the largest set in which each has a link in from it and a link
    out to it (unique: a union of such sets is one), peeled in one pass (:func:`_peel`):
    each element set aside takes one link from the counts of its neighbours."""
    i = np.asarray(i, dtype=np.int64)
    j = np.asarray(j, dtype=np.int64)
    by_i = np.argsort(i, kind="stable")
    by_j = np.argsort(j, kind="stable")
    alive = _peel(n, i, j, by_i, np.searchsorted(i[by_i], np.arange(n + 1)), by_j,
                  np.searchsorted(j[by_j], np.arange(n + 1)))
    return alive[i] & alive[j]


@njit(cache=True)
def _peel(n, i, j, by_i, i_off, by_j, j_off):
    """(n,) bool: the elements left when every element with no link out (count of links
    (x, ·) to living elements) or no link in is removed, until none is (queue order: the
    fixed point does not depend on it). ``by_i``/``i_off`` list the links of each i (CSR),
    ``by_j``/``j_off`` those of each j."""
    out_count = i_off[1:] - i_off[:-1]
    in_count = j_off[1:] - j_off[:-1]
    alive = np.ones(n, np.bool_)
    queue = np.empty(n, np.int64)
    q = 0
    for x in range(n):
        if out_count[x] == 0 or in_count[x] == 0:
            alive[x] = False
            queue[q] = x
            q += 1
    h = 0
    while h < q:
        x = queue[h]
        h += 1
        q = _unlink(x, i_off, by_i, j, in_count, alive, queue, q)  # links x -> y: y loses one in
        q = _unlink(x, j_off, by_j, i, out_count, alive, queue, q)  # links y -> x: y loses one out
    return alive


@njit(cache=True, inline="always")
def _unlink(x, off, by, other, count, alive, queue, q):
    """Take the links of x (CSR ``off``/``by``) from the counts of their ``other`` ends,
    queueing the ends left with none; the new queue length."""
    for k in range(off[x], off[x + 1]):
        y = other[by[k]]
        count[y] -= 1
        if count[y] == 0 and alive[y]:
            alive[y] = False
            queue[q] = y
            q += 1
    return q


@njit(cache=True)
def _greedy_match(n, i, j):
    """Successor of each element: links (i, j) taken in the given order while both are free."""
    nxt = np.full(n, -1, np.int64)
    taken = np.zeros(n, np.bool_)
    for k in range(len(i)):
        if nxt[i[k]] < 0 and not taken[j[k]]:
            nxt[i[k]] = j[k]
            taken[j[k]] = True
    return nxt


@njit(cache=True)
def _trace(nxt):
    """Walks of an injective successor map: (order, loop offsets, chain offsets) as in form_loops."""
    n = len(nxt)
    has_prev = np.zeros(n, np.bool_)
    for i in range(n):
        if nxt[i] >= 0:
            has_prev[nxt[i]] = True
    seen = np.zeros(n, np.bool_)
    chains = np.empty(n, np.int64)
    chain_off = [0]
    m = 0
    for i in range(n):  # open chains begin where nothing leads in
        if not has_prev[i]:
            k = i
            while k >= 0:
                seen[k] = True
                chains[m] = k
                m += 1
                k = nxt[k]
            chain_off.append(m)
    # the rest are cycles (nxt is injective); ascending i starts each at its smallest element
    loops = np.empty(n, np.int64)
    loop_off = [0]
    q = 0
    for i in range(n):
        q = walk_cycle(nxt, i, seen, loops, q)
        if q > loop_off[-1]:
            loop_off.append(q)
    order = np.concatenate((loops[:q], chains[:m]))
    return order, np.array(loop_off, np.int64), np.array(chain_off, np.int64) + q


def cells_of_loops(el, loop_offsets, loop_group, ref, inside):
    """Group the loops of each group into cells (§5.4 on the sphere).

    Loops i and j bound one cell iff every loop k of their group has i's and
    j's reference points on the same side (a loop's own reference point is on
    its left): the columns i and j of the group's side matrix are equal.
    ``inside`` is the point-in-left-region test (:func:`inside_loops` on the
    sphere; the EE-cells pass their square's).

    Returns
    -------
    (l,) int
        Cell id of each loop, numbered by the cells' smallest loops.
    """
    nl = len(loop_group)
    k, i = pairs_in_groups(loop_group)
    side = inside(el, loop_offsets, ref, k, ref[i]) | (k == i)
    # sort the pairs by (group, i, k): loop i's column is then one contiguous run
    order = np.lexsort([k, i])
    size = np.bincount(loop_group, minlength=loop_group.max() + 1 if nl else 0)[loop_group]
    column = side[order]
    cell = np.arange(nl)
    for m in np.unique(size[size > 1]):
        loops = np.flatnonzero(size == m)  # sorted by loop id; each is a column of length m
        cols = column[np.searchsorted(i[order], loops)[:, None] + np.arange(m)]
        key = np.concatenate([loop_group[loops, None], cols], axis=1)
        _, cls = unique_rows(key)
        smallest = np.full(cls.max() + 1, nl)
        np.minimum.at(smallest, cls, loops)
        cell[loops] = smallest[cls]
    _, cell = np.unique(cell, return_inverse=True)
    return cell.reshape(-1)
