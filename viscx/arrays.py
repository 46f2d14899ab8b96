"""Small array idioms shared across the package."""

import numpy as np


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
