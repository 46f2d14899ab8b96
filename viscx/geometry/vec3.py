"""Small 3-vectors in numba kernels, as tuples: no heap allocation in hot loops, and the
operations in numpy's order, so that the floats are numpy's.

Rows of arrays are read into tuples (:func:`row`), never taken as views: each view of an
array costs an atomic update of the array's reference count, and threads that share the
arrays contend on those updates (they made the skeleton's hull scans several times
slower).
"""

from numba import njit


@njit(cache=True, nogil=True)
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True)
def row(x, i):
    """Row i of an (n, 3) array as a tuple."""
    return (x[i, 0], x[i, 1], x[i, 2])


@njit(cache=True, nogil=True)
def row4(x, i):
    """Row i of an (n, 4) array as a tuple."""
    return (x[i, 0], x[i, 1], x[i, 2], x[i, 3])


@njit(cache=True, nogil=True)
def set_row(x, i, v):
    x[i, 0], x[i, 1], x[i, 2] = v[0], v[1], v[2]


@njit(cache=True, nogil=True)
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, nogil=True)
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, nogil=True)
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, nogil=True)
def axpy(p, s, d):
    """p + s d."""
    return (p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2])


@njit(cache=True, nogil=True)
def div(a, s):
    return (a[0] / s, a[1] / s, a[2] / s)
