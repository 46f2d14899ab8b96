"""Classify the open V-cell chains of a scene by their ends (docs/skeleton.md, "Furnished
buildings"): which kinds of missing boundary keep generator vertices incomplete.

    python benchmarks/open_vchains.py office:300          # buildings_skeleton's scene specs
    python benchmarks/open_vchains.py office:271:113 --vertex 140   # one vertex's chains

The V-cells are built as ``build_vcells`` builds them (elements, FormLoops, the join across
merged events). The open chains that keep their vertex incomplete (no point chain, not lying
on a closed loop of their group) are listed per vertex with the vertex's solid-angle sum;
each of their ends is compared with the elements of the vertex's sphere ending (for a
chain's start) or starting (for its end) within ``--chord``: one of the chain's own group
(on a closed loop, or on another chain), one whose pair differs in the up or the down
blocker alone, another pair, or none. Ends are counted by that partner, the image
(forward or antipodal), the event the VE arc ends at there, and whether the chain runs
along the great circle of a face plane through the vertex; the first vertices of each
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

from viscx.arrays import row_norms, unique_rows  # noqa: E402
from viscx.scene import build_scene  # noqa: E402
from viscx.skeleton import vcells as V  # noqa: E402
from viscx.skeleton.arcs import END_NAMES, build_arcs  # noqa: E402
from viscx.skeleton.candidates import build_nodes  # noqa: E402
from viscx.skeleton.loops import unique_elements  # noqa: E402
from viscx.tolerances import JOIN_CHORD  # noqa: E402


def chains_of(scene, arcs):
    """The elements and walks of every sphere, as :func:`vcells.build_vcells` forms them:
    (walk Elements, group of each walk element, loop_offsets, chain_offsets, (o,) bool
    whether each chain keeps its vertex incomplete)."""
    el = V.boundary_elements(scene, arcs)
    _, group = unique_rows(np.concatenate([el.vertex[:, None], el.pair], axis=1))
    keep = unique_elements(el, group, JOIN_CHORD)
    el, group = el.take(keep), group[keep]
    order, loop_offsets, chain_offsets = V.sphere_loops(scene, el, group)
    walk = el.take(order)
    harmless = V.point_chains(scene, walk, chain_offsets) | V.covered_chains(scene, walk, group[order], loop_offsets,
                                                                             chain_offsets)
    return walk, group[order], loop_offsets, chain_offsets, ~harmless


def face_plane_circle(scene, walk, index):
    """Whether each element runs along the great circle of a face plane through its vertex
    (a face whose plane holds the vertex within epsilon and the element's normal within 1e-6)."""
    normal = np.cross(walk.start[index], walk.end[index])
    normal /= np.maximum(row_norms(normal), 1e-300)[:, None]
    fn = scene.face_normal
    out = np.zeros(len(index), bool)
    for k, i in enumerate(index):
        x = scene.vertices[walk.vertex[i]]
        through = np.abs(fn @ x - scene.face_offset) <= scene.epsilon
        out[k] = np.any(np.abs(np.abs(fn[through] @ normal[k]) - 1) <= 1e-6)
    return out


def classify(scene, arcs, chord=1e-5, vertex=None):
    """Counter of open-chain ends by (partner, image, end event, in a face plane), examples,
    and the per-vertex list of chains."""
    walk, group, loop_offsets, chain_offsets, bad = chains_of(scene, arcs)
    n_loop = loop_offsets[-1]
    chain_of = np.full(len(walk), -1)
    chain_of[n_loop:] = np.repeat(np.arange(len(bad)), np.diff(chain_offsets))
    chains = np.flatnonzero(bad)
    if vertex is not None:
        chains = chains[walk.vertex[chain_offsets[chains]] == vertex]
    total = np.zeros(scene.vertices.shape[0])
    hc = arcs.half_cells
    counts, shown, listing = Counter(), {}, []
    for c in chains:
        lo, hi = chain_offsets[c], chain_offsets[c + 1]
        v = int(walk.vertex[lo])
        same_vertex = np.flatnonzero(walk.vertex == v)
        planar = face_plane_circle(scene, walk, np.arange(lo, hi))
        row = {"vertex": v, "pair": walk.pair[lo].tolist(), "elements": []}
        for i in range(lo, hi):
            h = walk.half_cell[i]
            a = hc.arc[h]
            row["elements"].append((int(hc.edge[h]), "anti" if walk.antipodal[i] else "fwd", int(walk.side[i]),
                                    [END_NAMES[int(t)] for t in arcs.end_type[a]], arcs.end_node[a].tolist(),
                                    np.round(arcs.interval[a], 6).tolist()))
        for which, i, at, others in (("start", lo, walk.start, walk.end), ("end", hi - 1, walk.end, walk.start)):
            near = same_vertex[row_norms(others[same_vertex] - at[i]) <= chord]
            near = near[near != i]
            p = walk.pair
            if np.any((group[near] == group[i]) & (chain_of[near] < 0)):
                partner = "own group (loop)"
            elif np.any(group[near] == group[i]):
                partner = "own group (chain)"
            elif np.any(np.all(p[near, 2:] == p[i, 2:], axis=1)):
                partner = "up differs"
            elif np.any(np.all(p[near, :2] == p[i, :2], axis=1)):
                partner = "down differs"
            elif len(near):
                partner = "another pair"
            else:
                partner = "none"
            h = walk.half_cell[i]
            a = hc.arc[h]
            # which end of the arc: forward +n runs s0 -> s1, the antipodal image reverses it
            rev = (walk.side[i] == 1) != bool(walk.antipodal[i])
            at_s1 = (which == "end") != rev
            event = END_NAMES[int(arcs.end_type[a, int(at_s1)])]
            key = (partner, "anti" if walk.antipodal[i] else "fwd", event, "plane" if planar[i - lo] else "-")
            counts[key] += 1
            if len(shown.setdefault(key, [])) < 4 and v not in shown[key]:
                shown[key].append(v)
        listing.append(row)
    return counts, shown, listing, len(chains)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="office:N[:SEED] or plan:NX:NZ[:SEED]")
    parser.add_argument("--top", type=int, default=30)
    parser.add_argument("--chord", type=float, default=1e-5, help="partner search radius on the sphere")
    parser.add_argument("--vertex", type=int, default=None, help="list this vertex's chains element by element")
    args = parser.parse_args(argv)
    scene = build_scene(scene_of(args.scene))
    arcs = build_arcs(scene, build_nodes(scene))
    counts, shown, listing, n = classify(scene, arcs, args.chord, args.vertex)
    vertices = Counter(r["vertex"] for r in listing)
    print(f"{args.scene}: {n} open chains keeping {len(vertices)} vertices incomplete: {dict(vertices)}")
    for key, k in counts.most_common(args.top):
        print(f"{k:6d}  {' / '.join(key)}  e.g. vertices {shown[key]}")
    if args.vertex is not None:
        for r in listing:
            print(r["pair"], *r["elements"], sep="\n    ")


if __name__ == "__main__":
    main()
