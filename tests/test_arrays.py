"""The array idioms of viscx.arrays against their plain numpy definitions."""

import numpy as np
import pytest

from viscx.arrays import (expand_ranges, first_of_rows, graph_components, loop_successors, reversed_loops, unique_rows,
                          unique_sorted)


@pytest.mark.parametrize("n", [0, 1, 7, 5000])
def test_unique_sorted_is_np_unique(n, rng):
    keys = rng.integers(-50, 50, n)
    assert np.array_equal(unique_sorted(keys), np.unique(keys))
    floats = rng.random(n).round(2)
    assert np.array_equal(unique_sorted(floats), np.unique(floats))


@pytest.mark.parametrize("n", [0, 1, 9, 5000])
@pytest.mark.parametrize("low, high", [(-2, 3), (0, 5), (0, 2**40)])
def test_unique_rows_is_np_unique_along_rows(n, low, high, rng):
    """Small ids (packed keys), negative entries and large ids (lexsort)."""
    rows = rng.integers(low, high, (n, 4))
    if n > 100:
        rows[n // 2:] = rows[: n - n // 2]  # repeats at every range
    u, inverse = unique_rows(rows)
    ref, ref_inverse = np.unique(rows, axis=0, return_inverse=True)
    assert np.array_equal(u, ref.reshape(-1, 4))
    assert np.array_equal(inverse, ref_inverse.reshape(-1))
    assert np.array_equal(u[inverse], rows)


@pytest.mark.parametrize("n", [0, 1, 9, 5000])
@pytest.mark.parametrize("low, high", [(-2, 3), (0, 5), (0, 2**40)])
def test_first_of_rows_is_np_unique_return_index(n, low, high, rng):
    rows = rng.integers(low, high, (n, 4))
    if n > 100:
        rows[n // 2:] = rows[: n - n // 2]
    ref = np.sort(np.unique(rows, axis=0, return_index=True)[1]) if n else np.zeros(0, np.int64)
    assert np.array_equal(first_of_rows(rows), ref)


def test_expand_ranges_is_the_concatenated_ranges():
    first, count = np.array([5, 0, 2]), np.array([2, 0, 3])
    row, index = expand_ranges(first, count)
    assert row.tolist() == [0, 0, 2, 2, 2]
    assert index.tolist() == [5, 6, 2, 3, 4]


def test_loop_successors_and_reversed_loops_loop_by_loop(rng):
    """Each loop's next element (its last to its first) and the loops turned where asked,
    against a loop-by-loop reference, empty loops included."""
    sizes = rng.integers(0, 6, 40)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    reverse = rng.random(40) < 0.5
    nxt, turned = [], []
    for j in range(40):
        ids = list(range(offsets[j], offsets[j + 1]))
        nxt += ids[1:] + ids[:1]
        turned += ids[::-1] if reverse[j] else ids
    assert loop_successors(offsets).tolist() == nxt
    assert reversed_loops(offsets, reverse).tolist() == turned


def test_row_norms_equal_numpys_norm_bit_for_bit():
    """arrays.row_norms (the skeleton's hot norms, one numba pass) sums a row's squares in
    numpy's order: equal to np.linalg.norm(x, axis=1) bit for bit, on any layout, NaN rows
    included, and hands other shapes and dtypes to numpy."""
    from viscx.arrays import row_norms

    rng = np.random.default_rng(3)
    for shape in [(20000, 3), (5, 3), (0, 3), (1000, 2), (10, 1), (6, 5)]:
        x = rng.normal(size=shape) * rng.uniform(0, 1e3, (shape[0], 1))
        x[: min(2, shape[0]), 0] = np.nan
        for y in (x, np.asfortranarray(x), x[::2], x.astype(np.float32)):
            a, b = np.linalg.norm(y, axis=1), row_norms(y)
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), (shape, y.dtype)


def test_graph_components_against_scipy():
    """The labels of scipy's connected_components on random graphs (isolated nodes, loops,
    repeated edges), and one component along a shuffled path of 10⁵ nodes."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(0)
    for _ in range(200):
        n = int(rng.integers(1, 200))
        a, b = rng.integers(0, n, (2, int(rng.integers(0, 2 * n))))
        count, label = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False)
        got = graph_components(n, a, b)
        assert got[0] == count and np.array_equal(got[1], label)
    path = rng.permutation(100_000)
    count, label = graph_components(100_000, path[:-1], path[1:])
    assert count == 1 and not label.any()
