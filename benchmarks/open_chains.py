"""Classify the open EE chains of a scene by their ends (docs/skeleton.md, "Furnished buildings",
open EE chains classified): which kinds of missing boundary keep edge pairs incomplete.

    python benchmarks/open_chains.py office:300          # buildings_skeleton's scene specs
    python benchmarks/open_chains.py plan:1:1 city:300   # city:N is random_boxes(N)

The EE-cells are built as ``build_eecells`` builds them, one chunk of squares (V2's segments
and the demotion of loops whose winding is not ±2π included). Each end of a chain that is no
point chain (``eecells.point_chains``) is compared with the elements of its square ending
(for a chain's start) or starting (for its end) within the join tolerance: one of the chain's
own group (its own chain's other end: a loop demoted for its winding; on a closed loop; or on
another chain), one whose pair differs in the front or the
back blocker alone, another pair, or none. Ends are counted by that partner, whether they lie
on a side of the square, the kind of the element (EEE, VE, XE arc or a segment of V2) and the
event its arc ends at there ("cut": a piece's end inside its arc); the first pairs of each
class are printed as examples.
"""

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from buildings_skeleton import scene_of  # noqa: E402
from scenes import random_boxes  # noqa: E402

from viscx.scene import build_scene  # noqa: E402
from viscx.skeleton import eecells as E  # noqa: E402
from viscx.skeleton.arcs import EEE, END_NAMES, VE, XE, build_arcs  # noqa: E402
from viscx.skeleton.candidates import build_nodes  # noqa: E402
from viscx.skeleton.loops import near_pairs  # noqa: E402
from viscx.tolerances import WINDING_TOLERANCE  # noqa: E402

KIND = {EEE: "EEE", VE: "VE", XE: "XE"}
SEGMENT = {E.SIDE: "side segment", E.PENCIL1: "pencil x1", E.PENCIL2: "pencil x2"}


def chains_of(scene, arcs):
    """The elements and walks of every square, as :func:`eecells.build_eecells` forms them:
    (Elements, order, loop_offsets, chain_offsets, point chains (o,) bool)."""
    arc, e1, e2 = E.arc_squares(scene, arcs)
    by_square = np.argsort(e1 * (1 << 32) + e2, kind="stable")
    squares = (arc[by_square], e1[by_square], e2[by_square])
    el = E.boundary_elements(scene, arcs, squares)
    loops = E._open_loops(scene, el, E._loops(scene, el))
    segments = E.open_segments(scene, el, loops[0], loops[2])
    if len(segments.e1):
        el, loops = E._with_segments(scene, arcs, squares, segments, el, loops)
    order, loop_offsets, chain_offsets = loops
    bad = np.abs(np.abs(E.windings(el.take(order), loop_offsets, bridged=True)) - 2 * np.pi) > WINDING_TOLERANCE
    order, loop_offsets, chain_offsets = E._demote(order, loop_offsets, chain_offsets, bad)
    return el, order, loop_offsets, chain_offsets, E.point_chains(scene, el.take(order), chain_offsets)


def classify(scene, arcs, examples=2):
    """Counter of chain ends by (partner, on side or inside, element kind, end event), and a
    few (e1, e2, x1, x2) examples of each."""
    el, order, _, chain_offsets, points = chains_of(scene, arcs)
    chain_of = np.full(len(el), -1)
    chain_of[order[chain_offsets[0]:]] = np.repeat(np.arange(len(points)), np.diff(chain_offsets))
    keep = np.flatnonzero(~points)
    first, last = order[chain_offsets[:-1][keep]], order[chain_offsets[1:][keep] - 1]
    tol = E.join_tolerance(scene, el.e1, el.e2)
    group = E._groups(el)
    _, square = np.unique(el.e1 * (1 << 32) + el.e2, return_inverse=True)
    square = square.reshape(-1)
    counts, shown = Counter(), {}
    for ends, at, others in ((last, el.end, el.start), (first, el.start, el.end)):
        n = len(ends)
        points_ = np.concatenate([at[ends], others])
        i, j = near_pairs(points_, points_, np.concatenate([square[ends], square]),
                          np.concatenate([tol[ends], tol]))
        mine = (i < n) & (j >= n)
        i, j = i[mine], j[mine] - n
        i, j = i[j != ends[i]], j[j != ends[i]]
        e, p = ends[i], el.pair
        same = group[j] == group[e]
        flags = {
            # a loop whose winding is no ±2π, demoted: its end meets its own start
            "own group (its own chain)": same & (chain_of[j] == chain_of[e]),
            "own group (on a loop)": same & (chain_of[j] < 0),
            "own group (on a chain)": same & (chain_of[j] >= 0),
            "front differs": np.all(p[j, :2] == p[e, :2], axis=1) & np.any(p[j, 2:] != p[e, 2:], axis=1),
            "back differs": np.all(p[j, 2:] == p[e, 2:], axis=1) & np.any(p[j, :2] != p[e, :2], axis=1),
            "another pair": np.ones(len(i), bool),
        }
        partner = np.full(n, "none", object)
        for name, flag in reversed(flags.items()):  # the first listed wins
            has = np.zeros(n, bool)
            has[i[flag]] = True
            partner[has] = name
        x = at[ends, :2]
        on_side = np.any((np.abs(x) <= tol[ends, None]) | (np.abs(x - 1) <= tol[ends, None]), axis=1)
        for k, end in enumerate(ends):
            if el.kind[end] == E.ARC:
                a = el.arc[end]
                # the element's end at this chain end: s1 for a + element's end, s0 for its start
                s = el.interval[end, int((at is el.end) == (el.side[end] == 0))]
                hit = np.flatnonzero(np.abs(arcs.interval[a] - s) <= 1e-12)
                kind, event = KIND[int(arcs.kind[a])], END_NAMES[int(arcs.end_type[a, hit[0]])] if len(hit) else "cut"
            else:
                kind, event = SEGMENT[int(el.kind[end])], "segment"
            key = (partner[k], "side" if on_side[k] else "inside", kind, event)
            counts[key] += 1
            if len(shown.setdefault(key, [])) < examples:
                shown[key].append((int(el.e1[end]), int(el.e2[end]), *np.round(x[k], 6).tolist()))
    return counts, shown, int(np.count_nonzero(points)), len(points)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="office:N[:SEED], plan:NX:NZ[:SEED] or city:N")
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args(argv)
    if args.scene.startswith("city:"):
        scene = random_boxes(int(args.scene.split(":")[1]))
    else:
        scene = build_scene(scene_of(args.scene))
    arcs = build_arcs(scene, build_nodes(scene))
    counts, shown, n_points, n_chains = classify(scene, arcs)
    print(f"{args.scene}: {n_chains} open chains, {n_points} of them point chains; "
          f"{sum(counts.values())} ends of the others")
    for key, n in counts.most_common(args.top):
        print(f"{n:7d}  {' / '.join(key)}  e.g. {shown[key]}")


if __name__ == "__main__":
    main()
