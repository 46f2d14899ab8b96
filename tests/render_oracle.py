"""Checks of rendered images against a Monte Carlo reference (tests only)."""

import numpy as np


def noise_check(exact, mean, stderr):
    """Whether an image agrees with a Monte Carlo reference to the reference's noise.

    Over the values with a non-zero standard error s (n of them), with e = exact − mean:
    for an exact image E[e²] = E[s²] pixel by pixel, so mean(e² − s²) is zero within 4 of
    its standard errors (sd(e² − s²)/√n: the pixels near the light dominate both sums and
    small hit counts make e/s heavy-tailed, so the spread is measured, not taken from a
    normal χ²). In particular RMSE ≤ the noise level sqrt(mean(s²)) up to that tolerance
    (the issue's criterion), and a wrong noise estimate fails it too.

    Returns
    -------
    ok : bool
    details : dict
    """
    live = stderr > 0
    e2 = ((exact - mean)[live]) ** 2
    s2 = stderr[live] ** 2
    n = int(live.sum())
    gap, tol = float(np.mean(e2 - s2)), float(4 * np.std(e2 - s2) / np.sqrt(n))
    d = {"n": n, "rmse": float(np.sqrt(e2.mean())), "noise": float(np.sqrt(s2.mean())),
         "gap": gap, "tol": tol, "ratio": float(np.sqrt(e2.mean() / s2.mean()))}
    return abs(gap) <= tol, d


def seam_pixels(image, label, face, noise, reference=None):
    """Pixels darker than both of their neighbours across a region boundary by more than
    the noise (the "black seams" of Hoberock et al. Fig. 9): along rows and columns, a pixel p
    between neighbours a and b that see the same face as p, with a region boundary
    between a and b, and lum(p) < min(lum(a), lum(b)) − noise(p).

    A shadow one pixel wide is such a minimum for real (the tall block's umbra on the red
    wall of the Cornell box at 64 × 64 is); with a ``reference`` image a pixel is a seam
    only when it is also darker than the reference there by more than 4 noise(p).

    image, reference : (h, w, 3) float; label, face : (h, w) int; noise : (h, w) float.
    Returns (k, 2) int: rows and columns of the seam pixels.
    """
    w = np.array([0.2126, 0.7152, 0.0722])
    lum = image @ w
    # rounding of an exact zero (1e-17) is not a seam
    noise = np.maximum(noise, 1e-12 * float(np.abs(lum).max()))
    bad = np.zeros(lum.shape, bool)
    for axis in (0, 1):
        a = np.roll(lum, 1, axis=axis)
        b = np.roll(lum, -1, axis=axis)
        la, lb = np.roll(label, 1, axis=axis), np.roll(label, -1, axis=axis)
        fa, fb = np.roll(face, 1, axis=axis), np.roll(face, -1, axis=axis)
        across = ((la != label) | (lb != label)) & (fa == face) & (fb == face) & (face >= 0)
        inner = np.ones(lum.shape, bool)
        if axis == 0:
            inner[[0, -1], :] = False
        else:
            inner[:, [0, -1]] = False
        bad |= inner & across & (lum < np.minimum(a, b) - noise)
    if reference is not None:
        bad &= lum < reference @ w - 4 * noise
    return np.argwhere(bad)
