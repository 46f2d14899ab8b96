"""Small array idioms shared across the package."""

import numpy as np
from numba import njit


def expand_ranges(first, count):
    """Concatenated ranges ``first[i] .. first[i] + count[i] - 1``, with the row ``i`` each
    element came from (a CSR gather without a Python loop).

    Parameters
    ----------
    first, count : (n,) int

    Returns
    -------
    row : (m,) int64
        ``m = count.sum()``.
    index : (m,) int64
    """
    count = np.asarray(count, dtype=np.int64)
    row = np.repeat(np.arange(len(count)), count)
    start = np.cumsum(count) - count
    return row, np.repeat(np.asarray(first, dtype=np.int64), count) + np.arange(int(count.sum())) - start[row]


def loop_successors(offsets):
    """(m,) int64: for each element of the loops packed at ``offsets`` (l + 1,) int, the
    index of the next element of its loop (a loop's last goes to its first)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    out = np.arange(int(offsets[-1]), dtype=np.int64) + 1
    full = offsets[1:] > offsets[:-1]
    out[offsets[1:][full] - 1] = offsets[:-1][full]
    return out


def reversed_loops(offsets, reverse):
    """(m,) int64: the indices 0 .. m − 1 of the loops packed at ``offsets`` (l + 1,) int,
    each loop j in reverse order where ``reverse[j]`` (l,) bool (a gather that turns them)."""
    offsets = np.asarray(offsets, dtype=np.int64)
    sizes = np.diff(offsets)
    out = np.arange(int(offsets[-1]), dtype=np.int64)
    back = np.repeat(np.asarray(reverse, bool), sizes)
    out[back] = (np.repeat(offsets[:-1] + offsets[1:] - 1, sizes) - out)[back]
    return out


def unique_sorted(keys):
    """The distinct values of ``keys``, ascending: ``np.unique(keys)`` by a sort.

    numpy 2.4's ``np.unique`` without ``return_*`` takes a hash table, which is about
    100 times slower than sorting on millions of distinct integers (6 M int64: 6 s
    against 0.04 s); the hot paths use this instead.

    Parameters
    ----------
    keys : (n,) array

    Returns
    -------
    (u,) array
    """
    s = np.sort(np.asarray(keys).reshape(-1))
    return s[np.r_[True, s[1:] != s[:-1]]] if len(s) else s


def unique_rows(rows):
    """The distinct rows of an integer array, in lexicographic order, and the index of each
    input row among them: ``np.unique(rows, axis=0, return_inverse=True)`` by one sort of
    the rows packed into int64 keys where they fit (small non-negative ids), else by one
    lexsort (4 to 10 times faster on millions of rows).

    Parameters
    ----------
    rows : (n, k) int

    Returns
    -------
    unique : (u, k) int
    inverse : (n,) int64
    """
    rows = np.asarray(rows)
    n, k = rows.shape
    bits = int(rows.max()).bit_length() if n else 0
    if n and rows.min() >= 0 and bits * k <= 63:
        key = np.zeros(n, dtype=np.int64)
        for col in rows.T:
            key = (key << bits) | col.astype(np.int64)
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        new = np.ones(n, dtype=bool)
        new[1:] = sorted_key[1:] != sorted_key[:-1]
    else:
        order = np.lexsort(rows.T[::-1])
        s = rows[order]
        new = np.ones(n, dtype=bool)
        new[1:] = np.any(s[1:] != s[:-1], axis=1)
    inverse = np.empty(n, dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return rows[order[new]], inverse


def first_of_rows(rows):
    """Where each distinct row of an integer array first occurs, ascending: the sorted
    ``np.unique(rows, axis=0, return_index=True)[1]`` by :func:`unique_rows` (its packed
    sort where the rows fit; ``np.unique`` on rows sorts them as a structured view, 10
    times slower on millions).

    Parameters
    ----------
    rows : (n, k) int

    Returns
    -------
    (u,) int64
    """
    _, inverse = unique_rows(rows)
    order = np.argsort(inverse, kind="stable")  # within a row's run, input order
    start = np.r_[True, inverse[order][1:] != inverse[order][:-1]] if len(order) else np.zeros(0, bool)
    return np.sort(order[start])


@njit(cache=True)
def walk_cycle(successor, start, seen, order, k):
    """Follow ``successor`` from ``start`` until an element already ``seen``, appending each
    element met to ``order`` from position ``k`` and marking it seen (in place).

    Parameters
    ----------
    successor : (n,) int64
        The next element of each element.
    start : int
    seen : (n,) bool
    order : (n,) int64
    k : int
        Elements already written to ``order``.

    Returns
    -------
    int
        ``k`` plus the number of elements walked.
    """
    h = start
    while not seen[h]:
        seen[h] = True
        order[k] = h
        k += 1
        h = successor[h]
    return k


def graph_components(n, a, b):
    """The connected components of the undirected graph on ``n`` nodes with the edges
    ``(a[k], b[k])``: ``(count, label)``, ``label`` (n,) int64 numbered 0, 1, … in the order
    of each component's smallest node (the labels of ``scipy.sparse.csgraph.
    connected_components``). Hooking and pointer jumping (Shiloach and Vishkin): every
    round hooks the root of each edge's larger label onto the smaller, then makes every
    node point to its root; O(log n) rounds of numpy. (For the form factors' closed
    solids: importing scipy's graph module costs ~0.15 CPU s, a tenth of a small matrix.)

    Parameters
    ----------
    n : int
    a, b : (e,) int
    """
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    root = np.arange(n, dtype=np.int64)
    while True:
        ra, rb = root[a], root[b]
        if np.array_equal(ra, rb):
            break
        np.minimum.at(root, np.maximum(ra, rb), np.minimum(ra, rb))
        while True:  # every node to its root (the smallest node of what is joined so far)
            up = root[root]
            if np.array_equal(up, root):
                break
            root = up
    smallest, label = np.unique(root, return_inverse=True)
    return len(smallest), label.astype(np.int64)


def bounding_diagonal(vertices):
    """Length of the diagonal of the points' bounding box; inf where it overflows float64
    (coordinates so large that distances between them cannot be computed).

    Parameters
    ----------
    vertices : (n, 3) float
    """
    if len(vertices) == 0:
        return 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        return float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))


def row_norms(x):
    """``np.linalg.norm(x, axis=1)`` of (n, k) float64 rows, bit for bit, about four times
    faster: numpy sums the squares of a row in order, ((x0² + x1²) + x2²), with a reduction
    whose inner loop of 2 or 3 items costs more than the arithmetic; here one numba pass.
    Other shapes and dtypes (float32 rows are summed in float32 by numpy) go to numpy.

    Parameters
    ----------
    x : (n, k) float

    Returns
    -------
    (n,) float
    """
    x = np.asarray(x)
    if x.ndim != 2 or x.dtype != np.float64 or x.shape[1] > 3:
        return np.linalg.norm(x, axis=1)
    return _row_norms(x)


@njit(cache=True, nogil=True)
def _row_norms(x):
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        s = 0.0
        for k in range(x.shape[1]):
            s += x[i, k] * x[i, k]  # (0 + a) is a: the same sums as numpy's
        out[i] = np.sqrt(s)
    return out
