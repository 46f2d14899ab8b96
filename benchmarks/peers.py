"""Side by side with pyviewfactor on a partly occluded pair of squares (reports, never asserts).

pyviewfactor computes unoccluded polygon-to-polygon view factors exactly (a double contour
integral) and decides occlusion all-or-nothing per pair of faces, from one ray between
their centroids; a partly occluded pair is right only after meshing both faces finely.
viscx integrates the occluded pair with an exact integrand and an error estimate.

Run with a Python that has pyviewfactor (a side environment, never a viscx dependency),
the ``viscx`` command on PATH (or in $VISCX):

    python -m venv /tmp/peers && /tmp/peers/bin/pip install pyviewfactor
    /tmp/peers/bin/python benchmarks/peers.py

The scene: I = [0, 1]² at z = 0 facing up, J = [0, 1]² at z = 1 facing down, and an
occluder at z = 0.5 covering x ∈ [0.45, 2] (over half of the pair, and the centroid ray).
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

OCCLUDER_X = 0.45


def squares(n, z, flip):
    """The n × n cells of [0, 1]² at height z, counter-clockwise about +z (or -z)."""
    cells = []
    for i in range(n):
        for j in range(n):
            x0, x1, y0, y1 = i / n, (i + 1) / n, j / n, (j + 1) / n
            quad = [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]
            cells.append(quad[::-1] if flip else quad)
    return cells


def pyviewfactor_F(n):
    """F(I → J) by pyviewfactor with I and J cut into n × n cells each: the sum over cell
    pairs of the unoccluded factor times the centroid-ray visibility, area-weighted."""
    import pyvista as pv
    import pyviewfactor as pvf

    def quad(points):
        return pv.PolyData(np.asarray(points, dtype=float), faces=[4, 0, 1, 2, 3])

    occ = quad([[OCCLUDER_X, -1, 0.5], [2, -1, 0.5], [2, 2, 0.5], [OCCLUDER_X, 2, 0.5]]).triangulate()
    emit = [quad(c) for c in squares(n, 0.0, False)]
    recv = [quad(c) for c in squares(n, 1.0, True)]
    total = 0.0
    for a in emit:
        for b in recv:
            visible, _ = pvf.get_obstruction(b, a, occ)
            if visible:
                total += pvf.compute_viewfactor(b, a)  # F(a -> b)
    return total / (n * n)  # each emitting cell is 1/n² of I


def viscx_F(tmp):
    obj = Path(tmp) / "pair.obj"
    obj.write_text("\n".join([
        "o emitter", "v 0 0 0", "v 1 0 0", "v 1 1 0", "v 0 1 0", "f 1 2 3 4",
        "o receiver", "v 0 0 1", "v 0 1 1", "v 1 1 1", "v 1 0 1", "f 5 6 7 8",
        "o occluder", f"v {OCCLUDER_X} -1 0.5", "v 2 -1 0.5", "v 2 2 0.5", f"v {OCCLUDER_X} 2 0.5", "f 9 10 11 12",
    ]) + "\n")
    viscx = os.environ.get("VISCX", "viscx")
    h5 = Path(tmp) / "pair.h5"
    subprocess.run([viscx, "-q", "build", str(obj), "-o", str(h5)], check=True)
    t0 = time.perf_counter()
    out = subprocess.run([viscx, "-q", "formfactor", "groups", str(h5), "--from-group", "emitter", "--to-group", "receiver"],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out), time.perf_counter() - t0


def monte_carlo_F(n_rays, rng):
    """Cosine-weighted rays from uniform points of I: the fraction reaching J past the occluder."""
    p = np.column_stack([rng.random((n_rays, 2)), np.zeros(n_rays)])
    u1, u2 = rng.random(n_rays), rng.random(n_rays)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    d = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)])
    at_j = p + d / d[:, 2:3]
    at_occ = p + 0.5 * d / d[:, 2:3]
    hit = (at_j[:, 0] >= 0) & (at_j[:, 0] <= 1) & (at_j[:, 1] >= 0) & (at_j[:, 1] <= 1) & (at_occ[:, 0] < OCCLUDER_X)
    f = hit.mean()
    return f, np.sqrt(f * (1 - f) / n_rays)


def main():
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as tmp:
        exact, seconds = viscx_F(tmp)
    F = exact["F"]
    mc, se = monte_carlo_F(4_000_000, rng)
    print(f"viscx: F = {F:.10f} (estimated error {exact.get('error', float('nan')):.1e}), {seconds:.2f} s for the whole command")
    print(f"Monte Carlo, 4e6 rays: F = {mc:.6f} ± {se:.6f} (viscx is {(F - mc) / se:+.2f} sigma away)")
    print("| pyviewfactor cells per square | F | relative error | seconds |")
    print("|---:|---:|---:|---:|")
    for n in (1, 2, 4, 8, 16):
        t0 = time.perf_counter()
        f = pyviewfactor_F(n)
        dt = time.perf_counter() - t0
        print(f"| {n * n} | {f:.6f} | {(f - F) / F:+.2%} | {dt:.2f} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
