"""The 2-D visibility complex of disjoint convex objects (Pocchiola–Vegter; Orti et al. §3).

Elements (Orti et al. §3.2), all sets of maximal free segments:

- **vertex**: a free bitangent — a segment tangent to two objects k1, k2 (k1's tangent
  point first along the line) whose maximal free extension ends on a *tail* t and a
  *head* h (−1 = blue sky).  Every pair of objects has four common tangents (two outer,
  two inner); those whose segment between the tangent points is free are vertices.
- **edge**: an arc of a tangency curve of one object k between two consecutive vertices:
  segments tangent to k, with tail t and head h fixed along the arc.
- **face**: a connected set of maximal free segments with the same pair of end objects.

Incidences: an edge (k; t, h) is incident to the three faces (t,k), (k,h), (t,h) and bounded
by two vertices; a vertex (k1, k2; t, h) is incident to four edges (two arcs on k1's curve,
two on k2's) and six faces (t,k1), (k1,k2), (k2,h), (t,k2), (k1,h), (t,h); a face is bounded
by two chains (its upper and lower boundary in the (θ, u) dual).

How it is built (any method O(m log n) in practice is allowed by the issue):

1. Candidates: the 4 common tangents of every pair, in closed form per support-function
   piece (:func:`kernels.all_bitangents`).
2. Each candidate segment is tested for freeness and extended to its tail and head by a
   grid walk (:func:`kernels.classify_bitangents`; early exit on the first blocker).
3. Edges: we work on the *oriented* double cover (θ ∈ [0, 2π)), where every vertex occurs
   twice (θ and θ + π, sides swapped).  Sorting the vertex occurrences along each of the
   2n tangency curves gives the edges between consecutive vertices.  The tail and head of
   each edge follow from its end vertices (checked against both ends).
4. Faces: an edge has three face *slots*; at a vertex the four edges pairwise share the six
   faces, which glues slots into connected components (union–find) = the faces.
5. Quotient: the reversal (θ, u) → (θ + π, −u) maps every oriented element to its *twin*;
   the stored complex keeps one representative of each pair (edges starting at θ < π,
   faces oriented from the smaller object id, the sky being −1).

The form factors use the oriented faces: the lines leaving O_a and next meeting O_b form the
oriented face a→b, whose dual area A_ab (θ ∈ [0, 2π)) equals the area of the unoriented
face over θ ∈ [0, π).  The lines meeting O_a have measure 2 L_a when each is counted once per
side it leaves O_a from (θ over [0, 2π)), so

    F_ab = A_ab / (2 L_a)         (Orti et al. §4.1 writes L_a, the [0, π) area, see docs)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from viscx.errors import ViscxError
from viscx.flatland import kernels as K
from viscx.flatland.scene import SKY, Scene

TWO_PI = 2.0 * math.pi
L, R = 0, 1
# two candidate lines closer than this in θ (and than TOL_U × the scene diagonal in u) are
# one line (rounding of the closed forms is ~1e-13 at 1e4 objects)
TOL_THETA = 1e-9
TOL_U = 1e-9
# a candidate joins a degenerate line when its two objects touch it within JOIN × the line
# tolerance (degenerate_lines): above the tolerance that makes lines degenerate, so that an
# object found within it is never half in (hysteresis); below the contact tolerance
# (scene.CONTACT_TOL = 4 × it), so that two entries of one line on its two sides that
# overlap along it are a contact (opened), never two disjoint objects on one line
JOIN = 2.0
# the gaps that open the contacts of touching objects (Scene.opened), relative to the scene
# diagonal, tried in this order: the direction of a line between the two sides of an
# opened contact is known to ~1e-16 |x| / γ, so γ stays well above TOL_THETA × |x|, and far
# below the features of a layout (at most a quarter of each object's width)
OPEN_RELS = (1e-6, 2.3e-6, 4.3e-7)
# the perturbation of resolve_degenerate: δ(x) = 1 + w (x − X0)², X0 = √2 − 1 so that no two
# positions of a real layout are symmetric about it, w = π/2 on the left side (unrelated
# constants: three perturbed contacts of a lattice line are then never collinear)
_X0 = math.sqrt(2.0) - 1.0
_W_LEFT = 0.5 * math.pi

# slots of an edge (object k, tail t, head h): the three faces it bounds
SLOT_TK, SLOT_KH, SLOT_TH = 0, 1, 2


@dataclass
class FlatComplex:
    """The visibility complex of a flatland scene plus its form factors.

    Vertex arrays (m,): ``v_key`` int64 candidate key (pair, kind, root: stable id order),
    ``v_obj`` (m, 2) int64 (k1, k2), ``v_support`` (m, 2) int64 (global support-point index
    of each tangent point), ``v_side`` (m, 2) int8 (side of k1, k2: 1 = right of
    the line, 0 = left), ``v_tail``, ``v_head`` int64 (−1 = sky), ``v_theta`` float64 in
    [0, π), ``v_p``, ``v_q`` (m, 2) tangent points, ``v_length`` |pq| (Orti et al.'s d_e),
    ``v_seg`` (m, 4) the maximal free segment (sky ends clipped at the scene box + 1 %),
    ``v_edges`` (m, 4) (k1 before, k1 after, k2 before, k2 after), ``v_faces`` (m, 6)
    ((t,k1), (k1,k2), (t,k2), (k1,h), (t,h), (k2,h)).

    Edge arrays (E,): ``e_obj``, ``e_side``, ``e_tail``, ``e_head``, ``e_verts`` (E, 2)
    (start, end vertex; −1 for a full loop), ``e_theta`` (E, 2) θ0 < θ1 (θ0 in [0, π)),
    ``e_integral`` ∫u dθ, ``e_arclength`` (Orti et al.'s d_c), ``e_faces`` (E, 3) (slots
    (t,k), (k,h), (t,h)).

    Face arrays (F,): ``f_pair`` (F, 2) (a, b) oriented a→b, ``f_area`` (dual area, method
    a), ``f_strings`` (signed vertex/edge sum, method b), ``f_bounded``; boundary chains as
    CSR ``f_edge_start`` / ``f_edge`` / ``f_edge_upper`` / ``f_edge_reversed`` and vertices
    ``f_vert_start`` / ``f_vert`` / ``f_vert_sign`` (+1 extremal, −1 chain vertex, 0 a smooth
    boundary point).

    Form factors: ``F_area``, ``F_strings`` (n, n + 1), last column the blue sky.
    """

    scene: Scene
    eps: float
    arrays: dict
    # in memory only (not written): the topology's internal state and the candidates'
    # blockers, which :func:`viscx.flatland.dynamic.move` updates locally
    state: dict | None = None
    blockers: np.ndarray | None = None
    # read from a file: its ``update`` group (dynamic.update_arrays), made into the state
    # and blocker table by the first update
    stored: dict | None = None

    def __getattr__(self, name):
        arrays = self.__dict__.get("arrays")
        if arrays is not None and name in arrays:
            return arrays[name]
        raise AttributeError(name)

    def __repr__(self):
        return (f"FlatComplex(n_objects={self.scene.n}, vertices={self.n_vertices}, edges={self.n_edges}, "
                f"faces={self.n_faces})")

    @property
    def n_vertices(self):
        return int(self.arrays["v_key"].shape[0])

    @property
    def n_edges(self):
        return int(self.arrays["e_obj"].shape[0])

    @property
    def n_faces(self):
        return int(self.arrays["f_pair"].shape[0])


# ----------------------------------------------------------------------------- candidates
def scene_kernel_args(scene: Scene):
    A, cumG, cumS, perimeter = scene.pieces()
    return A, cumG, cumS, perimeter


def default_eps(scene: Scene) -> float:
    bb = scene.bounding_boxes()
    diag = math.hypot(bb[:, 2].max() - bb[:, 0].min(), bb[:, 3].max() - bb[:, 1].min())
    return 1e-9 * max(diag, 1e-300)


def candidates(scene: Scene, pairs=None):
    """Candidate bitangents (the 4 common tangents of every pair), canonical orientation.

    Parameters
    ----------
    pairs : (P, 2) int64, optional  object pairs (i < j); default all pairs.

    Returns a dict of (4P,) arrays: key, theta in [0, π), a, b, side_a, side_b, va, vb."""
    n = scene.n
    if pairs is None:
        ii, jj = np.triu_indices(n, 1)
        pairs = np.stack([ii, jj], axis=1).astype(np.int64)
    pa, pb = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    A, cumG, cumS, perim = scene.pieces()
    theta, va, vb, count = K.all_bitangents(pa, pb, scene.vert_start, scene.verts, scene.radius, A, 1e-12)
    bad = np.nonzero(count != 2)[0]
    if bad.size:
        i = bad[0] // 2
        raise ViscxError(f"degenerate pair: objects {scene.names[pa[i]]!r} and {scene.names[pb[i]]!r} "
                         f"have {count[bad[0]]} common tangents of one kind instead of 2 (degenerate; try --perturb)")
    P = pa.shape[0]
    a = np.repeat(pa, 4)
    b = np.repeat(pb, 4)
    combo = np.tile(np.array([0, 0, 1, 1]), P)
    root = np.tile(np.array([0, 1, 0, 1]), P)
    side_a = np.ones(4 * P, np.int8)
    side_b = np.where(combo == 0, 1, 0).astype(np.int8)
    # canonical orientation θ ∈ [−TOL_THETA, π − TOL_THETA): the reversed line swaps both
    # sides.  The window is shifted so that one line computed from different pairs (a
    # horizontal row of panel tips: θ = 1e-17 from one pair, π − 1e-16 from another) gets
    # one orientation and its copies can be grouped (:func:`resolve_degenerate`).
    theta = np.where(theta >= TWO_PI - TOL_THETA, theta - TWO_PI, theta)
    flip = theta >= math.pi - TOL_THETA
    theta = np.where(flip, theta - math.pi, theta)
    side_a = np.where(flip, 1 - side_a, side_a).astype(np.int8)
    side_b = np.where(flip, 1 - side_b, side_b).astype(np.int8)
    key = ((a * n + b) * 4 + 2 * combo + root).astype(np.int64)
    return dict(key=key, theta=theta, a=a, b=b, side_a=side_a, side_b=side_b, va=va, vb=vb)


def classify(scene: Scene, cand: dict, eps: float, todo=None, grid=None):
    """Freeness, order and tail/head of candidates (see :func:`kernels.classify_bitangents`).

    Candidates on one line with at least two others (the m(m−1)/2 pairs of a line touching
    m objects: a row of panel tips) are classified together from the line's blockers
    (:func:`_classify_lines`, one O(n) scan per line) instead of one grid walk each."""
    if grid is None:
        grid = K.build_grid(scene.bounding_boxes())
    N = cand["theta"].shape[0]
    todo = np.ones(N, bool) if todo is None else todo
    p, q = tangent_points(scene, cand)
    idx = np.nonzero(todo)[0]
    tol = line_tol(scene)
    args = (cand["theta"][idx], p[idx], q[idx], np.stack([cand["a"], cand["b"]], 1)[idx],
            np.stack([cand["side_a"], cand["side_b"]], 1)[idx].astype(np.int64),
            np.stack([cand["va"], cand["vb"]], 1)[idx], tol)
    on_line = np.zeros(N, bool)
    pre = _copies(scene, *args[:4], args[5], tol)
    group, rep, on_line[idx], joined = _scanned_lines(scene, *args, pre=pre)
    out = K.classify_bitangents(cand["theta"], cand["a"], cand["b"], cand["side_a"].astype(np.int64),
                                cand["side_b"].astype(np.int64), cand["va"], cand["vb"], todo & ~on_line, eps, tol,
                                *grid, scene.kind, scene.vert_start, scene.verts, scene.radius)
    if np.any(on_line):
        _classify_lines(scene, cand, p, q, group, rep, idx, on_line[idx], eps, out)
    # a free line passing within tol of a third object is a degenerate line too (the walk
    # finds it): its members, joined by the candidates of that object, are scanned whole
    seed = out[7][idx] & out[0][idx] & ~on_line[idx]
    if np.any(seed):
        group, rep, again, joined = _scanned_lines(scene, *args, seed=seed, pre=pre)
        redo = np.isin(group, np.unique(group[again & ~on_line[idx]]))
        _classify_lines(scene, cand, p, q, group, rep, idx, redo, eps, out)
        on_line[idx] |= again
    # the members of a line that joined others are seeds of it again among the vertices
    # (resolve_degenerate regroups the free ones)
    out[7][idx] |= on_line[idx] & joined
    return out


def _scanned_lines(scene, theta, p, q, obj, side, sup, tol, seed=None, pre=None):
    """:func:`degenerate_lines` and which candidates are classified by a scan of their line:
    those on a line with at least two others, or joined to one (they take its tail and
    head).  Returns (group, rep, scanned, joined), each like theta."""
    group, rep, joined = degenerate_lines(scene, theta, p, q, obj, side, sup, tol, seed, pre)
    size = np.bincount(group) if group.size else np.zeros(0, np.int64)
    return group, rep, (size[group] >= 3) | (joined & (size[group] >= 2)), joined


def line_tol(scene):
    """Distance below which two lines (in u) or a corner and a line are one (TOL_U × diagonal)."""
    return TOL_U * default_eps(scene) / 1e-9


def tangent_points(scene, cand):
    """(N, 2), (N, 2): the tangent points of the candidate lines on objects a and b."""
    th = cand["theta"]
    nrm = np.stack([-np.sin(th), np.cos(th)], 1)
    p = scene.verts[cand["va"]] + ((2.0 * cand["side_a"] - 1.0) * scene.radius[cand["a"]])[:, None] * nrm
    q = scene.verts[cand["vb"]] + ((2.0 * cand["side_b"] - 1.0) * scene.radius[cand["b"]])[:, None] * nrm
    return p, q


def line_groups(theta, u, tol):
    """(N,) int64 group ids of lines (θ, u): chains of θ gaps ≤ TOL_THETA, then of u gaps
    ≤ tol, i.e. the copies of one line computed from different pairs."""
    return _line_chains(theta, u, tol)[0]


def _line_chains(theta, u, tol):
    """:func:`line_groups` and the order that sorts them (group ids ascend along it)."""
    N = theta.shape[0]
    if N == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    o = np.argsort(theta, kind="stable")
    gth = np.empty(N, np.int64)
    gth[o] = np.concatenate([[0], np.cumsum(np.diff(theta[o]) > TOL_THETA)])
    # the order of (θ chain, u, index): o already has it but within the θ chains of two
    # or more lines (few), which are sorted again alone
    gs = gth[o]
    multi = np.zeros(N, bool)
    multi[:-1] = gs[1:] == gs[:-1]
    multi[1:] |= multi[:-1].copy()
    sub = np.sort(o[multi])
    o[multi] = sub[np.lexsort((u[sub], gth[sub]))]
    brk = np.concatenate([[True], (np.diff(gth[o]) != 0) | (np.diff(u[o]) > tol)])
    g = np.empty(N, np.int64)
    g[o] = np.cumsum(brk) - 1
    return g, o


def touches(scene, obj, side, sup, theta, u, tol):
    """(N,) bool: object ``obj`` lies on side ``side`` (R = 1: n·x ≤ u, L = 0: n·x ≥ u) of
    the line (θ, u) and touches it within ``tol`` at its support point ``sup`` — the
    rule by which :func:`contacts` takes an entry to be on a degenerate line.  A circle:
    its support value n·c ± r within tol of u; a polygon or segment: corner ``sup``
    within tol of the line and neither neighbouring corner beyond it by more than tol
    (by convexity the corner is then the object's extreme point in n)."""
    nrm = np.stack([-np.sin(theta), np.cos(theta)], -1)
    sg = 2.0 * side - 1.0  # +1: the object is on the right, its support is max n·x
    off = np.einsum("ij,ij->i", nrm, scene.verts[sup]) + sg * scene.radius[obj] - u
    ok = np.abs(off) <= tol
    s, cnt = scene.vert_start[obj], scene.vert_start[obj + 1] - scene.vert_start[obj]
    for step in (-1, 1):
        nb = s + np.mod(sup - s + step, np.maximum(cnt, 1))
        ok &= sg * (np.einsum("ij,ij->i", nrm, scene.verts[nb]) + sg * scene.radius[obj] - u) <= tol
    return ok


def degenerate_lines(scene, theta, p, q, obj, side, sup, tol, seed=None, pre=None, chunk=1 << 21):
    """Group candidate lines into degenerate lines, one test for every line.

    theta (N,) canonical directions, p, q (N, 2) tangent points, obj, side, sup (N, 2)
    the two objects, their sides and support points; ``seed`` (N,) bool candidates known
    to lie on a degenerate line (the walk's ``graze``); ``pre`` the copies computed by an
    earlier call on the same candidates (:func:`_copies`), where the call also keeps its
    join window and the joins it found (a later call with seeds tests its new lines only).  Returns (group (N,) int64,
    rep (N,) bool: one member per group whose line (θ, u) stands for the group's,
    joined (N,) bool: the group holds lines that are not copies of one another).

    First the copies of one line computed from different pairs (:func:`line_groups`:
    θ within ``TOL_THETA``, u within ``tol``).  A set of two copies or more, one running
    along a polygon edge, or a seed, is a degenerate line ℓ; then every other candidate
    whose two objects both touch ℓ within JOIN × ``tol`` on its sides (:func:`touches`)
    is on ℓ too, whatever its own θ: an object lifted by a gap g ≤ tol off ℓ (a box
    beside the ground line, a circle near a common tangent of two others) touches ℓ like
    the others, but its tangents to their corners at distance L along ℓ tilt by g / L,
    which can be far above ``TOL_THETA`` (near a contact, L = 2γ).  Grouping those by θ
    alone split one degenerate line into a resolved half and a simple half.  Both tangent
    points within JOIN × tol of ℓ bound the tilt: |sin Δθ| ≤ 2 JOIN tol / |pq|
    (circles: within a factor 2), which prunes the pairs tested.  Candidates that join
    one line's group merge their groups (the line's with theirs), closed under their
    entries (:func:`_close_lines`).  A line is its largest set of copies' member with
    the longest baseline |pq| (the best-determined direction)."""
    N = theta.shape[0]
    if N == 0:
        return np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, bool)
    pre = _copies(scene, theta, p, q, obj, sup, tol) if pre is None else pre
    chain, order, start, u, base, head = pre["chain"], pre["order"], pre["start"], pre["u"], pre["base"], pre["head"]
    G = head.size
    size = np.diff(start)
    along = pre["along"] if seed is None else pre["along"] | seed
    is_line = (size >= 2) | (np.bincount(chain, weights=along, minlength=G) > 0)
    # the joins found by an earlier call on the same copies are kept: a call with seeds
    # only adds lines, so it tests the candidates against its new lines alone
    done, ua, ub = pre.get("joins", (np.zeros(G, bool), [], []))
    if np.any(done & ~is_line):  # not a call that adds lines: test them all again
        done, ua, ub = np.zeros(G, bool), [], []
    lines = head[is_line & ~done]
    ua, ub = list(ua), list(ub)
    join = JOIN * tol
    if lines.size:
        if "window" not in pre:
            # candidates that may join: those in no line of their own of 3 or more copies
            cand = np.nonzero(size[chain] <= 2)[0]
            pre["window"] = cand, np.arcsin(np.minimum(1.0, 4.0 * join / np.maximum(base[cand], 1e-300))) + 2.0 * TOL_THETA
        cand, w = pre["window"]
        lt = theta[lines]
        o = np.argsort(lt)
        ext_t = np.concatenate([lt[o] - math.pi, lt[o], lt[o] + math.pi])
        ext_i = np.concatenate([lines[o]] * 3)
        tc = theta[cand]
        lo = np.searchsorted(ext_t, tc - w, "left")
        # a non-empty window: its first line within it (the second search only for those)
        near = np.nonzero(ext_t[np.minimum(lo, ext_t.size - 1)] <= tc + w)[0]
        near = near[lo[near] < ext_t.size]
        cand, lo = cand[near], lo[near]
        cnt = np.searchsorted(ext_t, tc[near] + w[near], "right") - lo
        step = max(1, chunk // max(1, int(cnt.max(initial=1))))
        for c0 in range(0, cand.size, step):
            cc, lc, nc = cand[c0:c0 + step], lo[c0:c0 + step], cnt[c0:c0 + step]
            ci = np.repeat(cc, nc)
            li = ext_i[np.repeat(lc - (np.cumsum(nc) - nc), nc) + np.arange(nc.sum())]
            keep = chain[ci] != chain[li]
            ci, li = ci[keep], li[keep]
            # the candidate's sides in the line's orientation
            flip = np.cos(theta[ci] - theta[li]) < 0
            on = np.ones(ci.size, bool)
            for e in (0, 1):
                s_ = np.where(flip, 1 - side[ci, e], side[ci, e])
                on &= touches(scene, obj[ci, e], s_, sup[ci, e], theta[li], u[li], join)
            ua.append(chain[ci[on]])
            ub.append(chain[li[on]])
    pre["joins"] = (is_line, ua, ub)
    rep = np.zeros(N, bool)
    if not ua or not sum(a.size for a in ua):
        rep[head] = True
        return chain, rep, np.zeros(N, bool)
    ua, ub = np.concatenate(ua), np.concatenate(ub)
    comp = connected_components(coo_matrix((np.ones(ua.size), (ua, ub)), shape=(G, G)), directed=False)[1]
    comp = _close_lines(scene, theta, obj, side, base, pre, comp.astype(np.int64), join)
    group = comp[chain]
    nchain = np.bincount(comp, minlength=G)
    joined = nchain[group] >= 2
    # the line of a joined group: its largest set of copies' (a member with a far end off
    # the line, the lifted object's, would tilt it), then the longest baseline
    rep[head[nchain[comp] == 1]] = True
    mem = np.nonzero(joined)[0]
    best = mem[np.lexsort((mem, -base[mem], -size[chain[mem]], group[mem]))]
    rep[best[np.concatenate([[True], np.diff(group[best]) != 0])]] = True
    return group, rep, joined


def _copies(scene, theta, p, q, obj, sup, tol):
    """The copies of lines among candidates (:func:`degenerate_lines`): chain (N,) their
    set, order / start the sets' members (CSR), u, base |pq|, head (G,) each set's
    longest-baseline member, along (N,) bool a candidate alone in its set running along a
    polygon edge."""
    nrm = np.stack([-np.sin(theta), np.cos(theta)], 1)
    u = np.einsum("ij,ij->i", nrm, p)
    chain, order = _line_chains(theta, u, tol)
    N, G = theta.shape[0], int(chain.max(initial=-1)) + 1
    start = np.concatenate([[0], np.cumsum(np.bincount(chain, minlength=G))])  # chain[order] ascends
    base = np.hypot(*(q - p).T)
    top = np.maximum.reduceat(base[order], start[:-1]) if G else np.zeros(0)
    is_top = base[order] == top[chain[order]]
    first = np.nonzero(is_top & np.concatenate([[True], ~is_top[:-1] | (np.diff(chain[order]) != 0)])[:N])[0]
    head = order[first[np.diff(chain[order][first], prepend=-1) != 0]]
    along = np.zeros(theta.shape[0], bool)
    # (tested only for the candidates alone in their set: a set of two copies or more is a
    # degenerate line whatever its members run along)
    lone = np.diff(start)[chain] == 1
    for e in (0, 1):
        poly = lone & (np.diff(scene.vert_start)[obj[:, e]] >= 2)
        if poly.all():  # (segments and polygons only: no gathers)
            along |= _on_edge(scene, obj[:, e], sup[:, e], nrm, tol)
        elif poly.any():
            poly = np.nonzero(poly)[0]
            along[poly] |= _on_edge(scene, obj[poly, e], sup[poly, e], nrm[poly], tol)
    return dict(chain=chain, order=order, start=start, u=u, base=base, head=head, along=along)


def near_degenerate(scene, theta, u, tol):
    """(L,) bool: the lines (θ, u) that some object touches neither exactly (to 1e-3 tol:
    rounding) nor clearly not (beyond 8 tol: twice the contact tolerance, as the closure
    of a joined line reaches past the join tolerance): a near-degenerate
    line, grouped by :func:`degenerate_lines` with candidates that a re-scan of the line
    alone would not see (the dynamic update rebuilds a zone holding one)."""
    out = np.zeros(np.shape(theta), bool)
    starts = scene.vert_start[:-1]
    for i, (t_, u_) in enumerate(zip(np.atleast_1d(theta), np.atleast_1d(u))):
        proj = scene.verts @ np.array([-math.sin(t_), math.cos(t_)])
        off = np.minimum(np.abs(np.maximum.reduceat(proj, starts) + scene.radius - u_),
                         np.abs(np.minimum.reduceat(proj, starts) - scene.radius - u_))
        out[i] = np.any((off > 1e-3 * tol) & (off <= 4.0 * JOIN * tol))
    return out


def _close_lines(scene, theta, obj, side, base, pre, comp, join):
    """Labels (G,) of the sets of copies after :func:`degenerate_lines` joined them
    (``comp``), closed under their entries: a line that joined others (rare: only
    near-degenerate scenes) also takes every candidate of two of its entries (objects and
    sides, in the orientation of its line) whose direction is within the window of its
    tangent points, with that candidate's set.  The join test is not transitive — an
    object 2.5 tol off a line ℓ may touch, within 2 tol, the line through it and an
    entry of ℓ that a third entry grazes — so the entries a line collects through its
    joined members bring all their common tangents along (the perturbation resolves them
    all as one line)."""
    chain, order, start = pre["chain"], pre["order"], pre["start"]
    size = np.diff(start)
    multi = np.nonzero(np.bincount(comp) >= 2)[0]
    if multi.size == 0:
        return comp
    n = scene.n
    pid = np.minimum(obj[:, 0], obj[:, 1]) * n + np.maximum(obj[:, 0], obj[:, 1])
    # candidates come by pair (key order): then no sort is needed
    porder = np.arange(pid.size) if np.all(pid[1:] >= pid[:-1]) else np.argsort(pid, kind="stable")
    spid = pid[porder]
    by_label = np.argsort(comp, kind="stable")  # the sets of copies of each label
    lstart = np.searchsorted(comp[by_label], np.arange(comp.max() + 2))
    parent = np.arange(lstart.size - 1)

    def root(x):
        while parent[x] != x:
            x = parent[x]
        return x

    def members(labels):
        sets = np.concatenate([by_label[lstart[h]:lstart[h + 1]] for h in labels])
        return np.concatenate([order[start[c]:start[c + 1]] for c in sets])

    for g in multi:
        if root(g) != g:
            continue
        labels = [g]
        while True:
            mem = members(labels)
            r = mem[np.lexsort((mem, -base[mem], -size[chain[mem]]))[0]]
            flip = np.cos(theta[mem] - theta[r]) < 0
            codes = np.unique(2 * obj[mem] + (side[mem] ^ flip[:, None]))
            ob = np.unique(codes // 2)
            i, j = np.triu_indices(ob.size, 1)
            want = ob[i] * n + ob[j]
            lo, hi = np.searchsorted(spid, want, "left"), np.searchsorted(spid, want, "right")
            cnt = hi - lo
            c = porder[np.repeat(lo - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())]
            fl = np.cos(theta[c] - theta[r]) < 0
            ok = np.isin(2 * obj[c] + (side[c] ^ fl[:, None]), codes).all(axis=1)
            ok &= np.abs(np.sin(theta[c] - theta[r])) <= 4.0 * join / np.maximum(base[c], 1e-300) + 2.0 * TOL_THETA
            new = {root(h) for h in np.unique(comp[chain[c[ok]]])} - {g}
            if not new:
                break
            for h in new:
                parent[h] = g
                labels.append(h)
    roots = parent.copy()
    while np.any(roots[roots] != roots):
        roots = roots[roots]
    return roots[comp]


def _classify_lines(scene, cand, p, q, group, rep, idx, mask, eps, out, chunk=1 << 22):
    """Classify the candidates ``idx`` line by line, into ``out`` (the arrays of
    :func:`kernels.classify_bitangents`), with the same rules as the grid walk: blocked
    by an object cut deeper than eps between the tangent points, tail / head the nearest
    such objects behind / beyond them.  Each line is its representative's (``rep``,
    :func:`degenerate_lines`; ``group``, ``rep`` and ``mask`` are given for the candidates
    ``idx``, the candidates classified are ``idx[mask]``)."""
    sel = np.nonzero(mask)[0]
    if sel.size == 0:
        return
    order = sel[np.lexsort((~rep[sel], group[sel]))]
    bounds = np.nonzero(np.diff(group[order]))[0] + 1
    # the objects touching the line within the join tolerance are its entries (perturbed
    # off it by resolve_degenerate), never its blockers
    eps_line = max(eps, JOIN * line_tol(scene))
    for line in np.split(idx[order], bounds):
        th = cand["theta"][line[0]]
        d = np.array([math.cos(th), math.sin(th)])
        o = p[line[0]]
        hk, ti, to = K.line_hits(o[0], o[1], d[0], d[1], eps_line, scene.kind, scene.vert_start, scene.verts,
                                 scene.radius)
        # members joined reversed (θ + π, :func:`degenerate_lines`) read the line backwards
        rev = np.cos(cand["theta"][line] - th) < 0
        for mem, sg, t_in, t_out in ((line[~rev], 1.0, ti, to), (line[rev], -1.0, -to, -ti)):
            if mem.size:
                _classify_on_line(cand, mem, sg * ((p[mem] - o) @ d), sg * ((q[mem] - o) @ d), hk, t_in, t_out, eps,
                                  out, max(1, chunk // max(1, hk.size)))


def _classify_on_line(cand, mem, tp, tq, hk, ti, to, eps, out, step):
    """:func:`_classify_lines` for the members ``mem`` of one line: tp, tq their tangent
    points' and ti, to the blockers' entry / exit parameters along the members' direction."""
    free, a_first, tail, head, tail_t, head_t, blocker = out[:7]
    af = tq >= tp
    s, e = np.minimum(tp, tq), np.maximum(tp, tq)
    a_first[mem] = af
    for c0 in range(0, mem.size, step):
        c = slice(c0, c0 + step)
        own = (hk[None, :] == cand["a"][mem[c], None]) | (hk[None, :] == cand["b"][mem[c], None])
        ahead = ~own & (to[None, :] > s[c, None] + eps)
        tin = np.where(ahead, ti[None, :], np.inf)
        j = np.argmin(tin, axis=1) if hk.size else np.zeros(mem[c].size, np.int64)
        first = tin[np.arange(tin.shape[0]), j] if hk.size else np.full(mem[c].size, np.inf)
        blocked = first < e[c] - eps
        behind = ~own & (ti[None, :] < s[c, None] - eps)
        tout = np.where(behind, to[None, :], -np.inf)
        jt = np.argmax(tout, axis=1) if hk.size else np.zeros(mem[c].size, np.int64)
        last = tout[np.arange(tout.shape[0]), jt] if hk.size else np.full(mem[c].size, -np.inf)
        m_ = mem[c]
        free[m_] = ~blocked
        blocker[m_] = np.where(blocked, hk[j] if hk.size else -1, -1)
        head[m_] = np.where(blocked, -2, np.where(np.isfinite(first), hk[j] if hk.size else -1, -1))
        head_t[m_] = np.where(np.isfinite(first), first - e[c], np.inf)
        tail[m_] = np.where(blocked, -2, np.where(np.isfinite(last), hk[jt] if hk.size else -1, -1))
        tail_t[m_] = np.where(np.isfinite(last), s[c] - last, np.inf)


def vertices_from(scene: Scene, cand: dict, cls) -> dict:
    """Vertex arrays (sorted by key) from classified candidates."""
    free, a_first, tail, head, tail_t, head_t = cls[:6]
    idx = np.nonzero(free)[0]
    af = a_first[idx]
    a, b = cand["a"][idx], cand["b"][idx]
    sa, sb = cand["side_a"][idx], cand["side_b"][idx]
    va, vb = cand["va"][idx], cand["vb"][idx]
    theta = cand["theta"][idx]
    d = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    nrm = np.stack([-d[:, 1], d[:, 0]], axis=1)
    pa = scene.verts[va] + ((2.0 * sa - 1.0) * scene.radius[a])[:, None] * nrm
    pb = scene.verts[vb] + ((2.0 * sb - 1.0) * scene.radius[b])[:, None] * nrm
    k1 = np.where(af, a, b)
    k2 = np.where(af, b, a)
    s1 = np.where(af, sa, sb).astype(np.int8)
    s2 = np.where(af, sb, sa).astype(np.int8)
    p = np.where(af[:, None], pa, pb)
    q = np.where(af[:, None], pb, pa)
    length = np.einsum("ij,ij->i", q - p, d)
    # maximal free segment; a sky end is clipped to the scene box enlarged by 1 %
    tt = np.where(np.isfinite(tail_t[idx]), tail_t[idx], 0.0)
    ht = np.where(np.isfinite(head_t[idx]), head_t[idx], 0.0)
    seg = np.concatenate([p - tt[:, None] * d, q + ht[:, None] * d], axis=1)
    seg = clip_sky_ends(scene, theta, p, q, tail[idx], head[idx], seg)
    sup = np.stack([np.where(af, va, vb), np.where(af, vb, va)], 1).astype(np.int64)
    V = dict(v_key=cand["key"][idx], v_obj=np.stack([k1, k2], 1).astype(np.int64), v_support=sup,
             v_side=np.stack([s1, s2], 1).astype(np.int8), v_tail=tail[idx].astype(np.int64),
             v_head=head[idx].astype(np.int64), v_theta=theta, v_p=p, v_q=q, v_length=length, v_seg=seg)
    if len(cls) > 7:  # lines found grazing a third object (resolve_degenerate consumes it)
        V["v_graze"] = cls[7][idx]
    return V


def resolve_degenerate(scene: Scene, V: dict) -> dict:
    """Degenerate free lines resolved by a symbolic perturbation (adds ``v_tau``).

    Under ε-visibility (a line blocks only where it cuts an object deeper than ε, see
    :func:`kernels.depth`) a line touching several objects inside one maximal free segment
    — the tips of a row of identical tilted panels, the tops of aligned columns, a lattice
    diagonal through corners — is free, and every pair of the objects it touches gives a
    free bitangent on it: the vertices are not simple (several tangency curves through one
    point of the dual, polygon edges along the line).  They are grouped here by line
    (θ within ``TOL_THETA``, u within ``TOL_U`` × the scene diagonal) and by the segment's
    tail and head, and each group is replaced by the simple vertices of the perturbed
    scene in which every touching object is pushed off the line by an infinitesimal
    δ(x) = 1 + w (x̃ − X0)², x̃ its contact position along the line scaled to [−1, 1]
    (strictly convex in x̃, so a row of tips on one side becomes a strictly convex chain
    and only consecutive objects see each other; :func:`kernels.local_arrangement` gives
    the vertices, tails, heads and tangent points).  The vertices keep θ*, and their order
    along a tangency curve inside the group is the infinitesimal offset ``v_tau``
    (0 elsewhere), which :func:`derive` uses as the second sort key: the edges between
    them have length 0, so dual areas and form factors are the limit of the perturbed
    scene's, i.e. the exact values of the unperturbed one.  The same rule resolves a
    single pair whose common tangent runs along a polygon edge (the tangent point is the
    edge's end that the perturbed line touches)."""
    m = V["v_key"].shape[0]
    V = dict(V)
    seed = V.pop("v_graze", None)
    V["v_tau"] = np.zeros(m)
    if m == 0:
        return V
    th = V["v_theta"]
    d = np.stack([np.cos(th), np.sin(th)], 1)
    nrm = np.stack([-d[:, 1], d[:, 0]], 1)
    u = np.einsum("ij,ij->i", nrm, V["v_p"])
    tol = line_tol(scene)
    # -- group by line, then by (tail, head): one maximal free segment each
    gline, rep, joined = degenerate_lines(scene, th, V["v_p"], V["v_q"], V["v_obj"],
                                          V["v_side"].astype(np.int64), V["v_support"], tol, seed)
    line_th = np.empty(int(gline.max()) + 1)
    line_th[gline[rep]] = th[rep]
    line_th = np.where(joined, line_th[gline], th)
    # a member joined reversed (θ ≈ the line's θ + π) has its tail and head swapped
    rev = np.cos(th - line_th) < 0
    tail, head = np.where(rev, V["v_head"], V["v_tail"]), np.where(rev, V["v_tail"], V["v_head"])
    n1 = scene.n + 1
    _, group = np.unique((gline * n1 + tail + 1) * n1 + head + 1, return_inverse=True)
    group = group.ravel()
    size = np.bincount(group)
    need = size[group] >= 2
    need |= _on_edge(scene, V["v_obj"][:, 0], V["v_support"][:, 0], nrm, tol)
    need |= _on_edge(scene, V["v_obj"][:, 1], V["v_support"][:, 1], nrm, tol)
    keep = np.ones(m, bool)
    gids = np.unique(group[need])
    # members of each segment, the first giving its θ, tail, head and ends: of a set of
    # copies the lowest key (as an update's re-scan of the line takes it), of a line that
    # joined others the longest baseline, in the direction of its representative
    order = np.lexsort((np.arange(m), np.where(joined, -np.abs(V["v_length"]), 0.0), group))
    end = np.cumsum(size)  # members of segment g: order[end[g] - size[g]:end[g]]
    for g in gids:
        idx = order[end[g] - size[g]:end[g]]
        keep[idx] = False
        at, fields = _resolve_line(scene, V, idx, line_th[idx[0]], rev, tol)
        keep[at] = True
        for name, val in fields.items():
            V[name][at] = val
    return {name: arr[keep] for name, arr in V.items()}


def _on_edge(scene, obj, sup, nrm, tol):
    """(m,) bool: the line (normal nrm) through support point sup of object obj also passes
    through a neighbouring corner (it runs along a polygon edge)."""
    vs = scene.vert_start
    cnt = np.diff(vs)
    out = np.zeros(obj.shape[0], bool)
    poly = cnt[obj] >= 2
    # each corner's neighbours, once per scene corner rather than once per line
    s = np.repeat(vs[:-1], cnt)
    c = np.repeat(np.maximum(cnt, 1), cnt)
    v = np.arange(s.size)
    for step in (-1, 1):
        edge = scene.verts[s + np.mod(v - s + step, c)] - scene.verts
        gap = np.einsum("ij,ij->i", nrm, edge[sup])
        out |= poly & (np.abs(gap) <= tol)
    return out


def contacts(scene, codes, d, n, tol):
    """Contacts of entries ``codes`` (2·object + side: R = 1 / L = 0) with a line of
    direction d, normal n: positions a ≤ b along d of the object's extreme points on the
    line (within tol), their support indices ja, jb and points pa, pb (E, 2).  One pass
    over the entries' support points (no per-entry Python)."""
    k, side = codes // 2, codes % 2
    s = scene.vert_start[k]
    cnt = scene.vert_start[k + 1] - s
    start = np.cumsum(cnt) - cnt
    ent = np.repeat(np.arange(k.size), cnt)
    vid = s[ent] + np.arange(ent.size) - start[ent]
    pts = scene.verts[vid] + ((2.0 * side - 1.0) * scene.radius[k])[ent][:, None] * n
    proj = pts[:, 0] * n[0] + pts[:, 1] * n[1]
    ext = np.where(side == R, np.maximum.reduceat(proj, start), np.minimum.reduceat(proj, start))
    on = np.abs(proj - ext[ent]) <= tol
    pos = pts[:, 0] * d[0] + pts[:, 1] * d[1]
    # first of the smallest / largest position among each entry's points on the line
    ia = np.lexsort((np.where(on, pos, np.inf), ent))[start]
    ib = np.lexsort((np.where(on, -pos, np.inf), ent))[start]
    return pos[ia], pos[ib], vid[ia], vid[ib], pts[ia], pts[ib]


def _resolve_line(scene, V, idx, th, rev, tol):
    """Rows (vertex index, {field: value}) of the perturbed vertices of one degenerate
    line of direction θ (see :func:`resolve_degenerate`): its members ``idx`` (vertex
    indices, the first one giving the tail, head and the segment's ends), ``rev`` (m,)
    bool the vertices that run the other way (θ + π: their ends and sides swap)."""
    r = rev[idx]
    obj, sd = V["v_obj"][idx], V["v_side"][idx].astype(np.int64)
    ends = np.where(r[:, None], 2 * obj[:, ::-1] + 1 - sd[:, ::-1], 2 * obj + sd)
    ent = np.unique(ends.ravel())
    n2 = 2 * scene.n  # members by objects and sides (four per pair along a segment)
    mkey = ends[:, 0] * n2 + ends[:, 1]
    mo = np.argsort(mkey)
    mkey, midx = mkey[mo], idx[mo]

    def member(ci, cj):
        key = ci * n2 + cj
        at = np.minimum(np.searchsorted(mkey, key), mkey.size - 1)
        return np.where(mkey[at] == key, midx[at], -1)

    i0 = idx[0]
    T, H = (V["v_head"][i0], V["v_tail"][i0]) if r[0] else (V["v_tail"][i0], V["v_head"][i0])
    seg0, seg1 = (V["v_seg"][i0, 2:], V["v_seg"][i0, :2]) if r[0] else (V["v_seg"][i0, :2], V["v_seg"][i0, 2:])
    return resolve_entries(scene, ent, float(th), int(T), int(H), seg0, seg1, tol, member)


def resolve_entries(scene, ent, th, T, H, seg0, seg1, tol, member):
    """The perturbed vertices of the maximal free segment (tail T, head H, ends seg0, seg1)
    of the degenerate line of direction θ touched by the entries ``ent`` (codes
    2·object + side).  ``member(ci, cj)`` names, for the entry codes of each vertex (first
    along the line, second), the vertex (its candidate) that carries it (−1: none).

    Returns (members (k,), {field: (k, ...) values})."""
    d = np.array([math.cos(th), math.sin(th)])
    n = np.array([-d[1], d[0]])
    ent = np.asarray(ent, np.int64)
    ca, cb, ja, jb, pa, pb = contacts(scene, ent, d, n, tol)
    o = np.lexsort((ent % 2, ent // 2, ca))
    xa, xb, ent, ja, jb, pa, pb = ca[o], cb[o], ent[o], ja[o], jb[o], pa[o], pb[o]
    obj = ent // 2
    # an object touching the line on both sides lies along it (a segment): two adjacent entries
    mate = np.full(ent.size, -1, np.int64)
    two = np.nonzero(obj[1:] == obj[:-1])[0]
    mate[two], mate[two + 1] = two + 1, two
    clash = (xa[1:] <= xb[:-1]) & (obj[1:] != obj[:-1])
    if np.any(clash):
        i = int(np.nonzero(clash)[0][0])
        raise ViscxError(f"objects {scene.names[obj[i]]!r} and {scene.names[obj[i + 1]]!r} touch the same "
                         "line at one point; flatland objects must be disjoint")
    right = ent % 2 == R
    lo, hi = xa.min(), xb.max()
    half = max(0.5 * (hi - lo), 1e-300)
    x = (0.5 * (xa + xb) - 0.5 * (lo + hi)) / half
    delta = 1.0 + np.where(right, 1.0, _W_LEFT) * (x - _X0) ** 2
    c = np.where(right, -delta, delta)
    # an object along the line is translated across it by a push of its own range
    # (0.25, 0.5], distinct from every one-sided push (|c| ≥ 1)
    c = np.where(mate >= 0, 0.5 / (1.0 + (x - _X0) ** 2), c)
    ci = 0.5 * (lo + hi)
    pi, pj, tau, tl, hd, ib, jb_ = K.local_arrangement(xa - ci, xb - ci, right, c, mate)
    at = member(ent[pi], ent[pj])
    if np.any(at < 0):
        i = int(np.nonzero(at < 0)[0][0])
        raise ViscxError(f"degenerate line through {scene.names[obj[pi[i]]]!r} and {scene.names[obj[pj[i]]]!r} "
                         "could not be resolved (a common tangent was not found as a candidate)")
    p = np.where(ib[:, None], pb[pi], pa[pi])
    q = np.where(jb_[:, None], pb[pj], pa[pj])
    start = np.where((tl < 0)[:, None], np.asarray(seg0)[None, :], pb[np.maximum(tl, 0)])
    end = np.where((hd < 0)[:, None], np.asarray(seg1)[None, :], pa[np.maximum(hd, 0)])
    tail = np.where(tl < 0, T, obj[np.maximum(tl, 0)])
    head = np.where(hd < 0, H, obj[np.maximum(hd, 0)])
    # sky ends clipped from the vertices' own tangent points, as a move re-clips them when
    # the scene box changes (the first member's, within the line tolerance of the line,
    # gave ends 1e-8 apart)
    seg = clip_sky_ends(scene, np.full(pi.size, th), p, q, tail, head, np.concatenate([start, end], 1))
    fields = dict(v_obj=np.stack([obj[pi], obj[pj]], 1), v_side=np.stack([ent[pi] % 2, ent[pj] % 2], 1).astype(np.int8),
                  v_theta=np.full(pi.size, th), v_tau=tau, v_tail=tail, v_head=head,
                  v_support=np.stack([np.where(ib, jb[pi], ja[pi]), np.where(jb_, jb[pj], ja[pj])], 1), v_p=p, v_q=q,
                  v_length=(q[:, 0] - p[:, 0]) * d[0] + (q[:, 1] - p[:, 1]) * d[1], v_seg=seg)
    # the offsets order the vertices along each curve: they must differ on one curve
    ent_id = np.concatenate([pi, pj])
    t2 = np.concatenate([tau, tau])
    o = np.lexsort((t2, ent_id))
    same = (np.diff(ent_id[o]) == 0) & (np.diff(t2[o]) <= 1e-12 * max(np.abs(tau).max(), 1e-300))
    if np.any(same):
        raise ViscxError("a degenerate line could not be resolved (two of its perturbed vertices coincide)")
    return at, fields


def clip_sky_ends(scene, theta, p, q, tail, head, seg):
    """(m, 4) segments with every sky end (tail or head −1) replaced by the point where the
    line leaves the scene's bounding box enlarged by 1 % (finite, checkable)."""
    d = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    bb = scene.bounding_boxes()
    lo, hi = bb[:, :2].min(axis=0), bb[:, 2:].max(axis=0)
    pad = 0.01 * (hi - lo).max() + 1e-12
    seg = seg.copy()
    back = p - _box_exit(p, -d, lo - pad, hi + pad)[:, None] * d
    far = q + _box_exit(q, d, lo - pad, hi + pad)[:, None] * d
    seg[:, :2] = np.where((tail < 0)[:, None], back, seg[:, :2])
    seg[:, 2:] = np.where((head < 0)[:, None], far, seg[:, 2:])
    return seg


def _box_exit(o, d, lo, hi):
    """(N,) distance along d from points o (inside the box) to the box boundary."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(d[:, 0] > 0, (hi[0] - o[:, 0]) / d[:, 0], np.where(d[:, 0] < 0, (lo[0] - o[:, 0]) / d[:, 0], np.inf))
        ty = np.where(d[:, 1] > 0, (hi[1] - o[:, 1]) / d[:, 1], np.where(d[:, 1] < 0, (lo[1] - o[:, 1]) / d[:, 1], np.inf))
    return np.minimum(tx, ty)


# ----------------------------------------------------------------------------- topology
# The topology is computed on the oriented double cover (θ ∈ [0, 2π)).  Its internal
# arrays (the *state*: the incidences sorted along the tangency curves, the edges starting
# at each, the face components of the edge slots) are what :mod:`dynamic` updates locally;
# :func:`canonical` turns a state into the stored arrays.  The helpers below are shared by
# the full derivation (:func:`derive`) and the local update.
def occurrences(V: dict) -> dict:
    """Per-occurrence arrays (2m,): o = 0 the stored line (occurrence v), o = 1 its reversal
    θ + π (occurrence m + v): the order along the line flips, both sides flip, tail and
    head swap.  K1/K2 objects, S1/S2 sides, T/H tail/head, TH θ, TAU offset, J1/J2 support
    points, LEN |pq|; X_AFTER / Z_AFTER: on K1's curve the (T→K2) edge is after the vertex /
    on K2's curve the (K1→H) edge is (derivation: f(θ) = u_K1 − u_K2 has slope d·(q − p) > 0
    at the vertex, so just after it the line tangent to K1 passes above K2's curve; it
    crosses K2 iff K2 is on its left (λ) side; symmetrically for K2)."""
    m = V["v_key"].shape[0]
    k1, k2 = V["v_obj"][:, 0], V["v_obj"][:, 1]
    s1, s2 = V["v_side"][:, 0].astype(np.int64), V["v_side"][:, 1].astype(np.int64)
    t, h = V["v_tail"], V["v_head"]
    th = V["v_theta"]
    ths = V.get("v_theta_sort", th)
    tau = V["v_tau"] if "v_tau" in V else np.zeros(m)
    cat = np.concatenate
    O = dict(K1=cat([k1, k2]), K2=cat([k2, k1]), S1=cat([s1, 1 - s2]), S2=cat([s2, 1 - s1]), T=cat([t, h]),
             H=cat([h, t]), TH=cat([th, th + math.pi]), THS=cat([ths, ths + math.pi]), TAU=cat([tau, tau]),
             J1=cat([V["v_support"][:, 0], V["v_support"][:, 1]]), J2=cat([V["v_support"][:, 1], V["v_support"][:, 0]]),
             LEN=cat([V["v_length"], V["v_length"]]))
    O["X_AFTER"] = O["S2"] == L
    O["Z_AFTER"] = O["S1"] == R
    return O


def incidences(O: dict, occ=None):
    """The incidences of occurrences ``occ`` (default all) on the tangency curves (curve id
    2·object + side): role 0 on K1's curve, 1 on K2's.  Returns (curve, θ, τ, occ, role),
    role-major; incidence id = occ + role · 2m."""
    occ = np.arange(O["K1"].shape[0]) if occ is None else occ
    cat = np.concatenate
    curve = cat([2 * O["K1"][occ] + O["S1"][occ], 2 * O["K2"][occ] + O["S2"][occ]])
    return (curve, cat([O["TH"][occ]] * 2), cat([O["TAU"][occ]] * 2), cat([occ, occ]),
            np.repeat(np.array([0, 1], np.int64), occ.shape[0]))


def edge_labels(scene, O, st, p):
    """Tail, head, θ range and end support points of the edges starting at sorted positions p
    (the arc of the curve from incidence p to the next one).  The tail and head follow from
    the start vertex and are checked against the end vertex.

    Returns th0, th1, tail, head, j0, j1 (each like p)."""
    q = st["nxt"][p]
    so, sr = st["s_occ"][p], st["s_role"][p]
    eo, er = st["s_occ"][q], st["s_role"][q]
    x_after, z_after = O["X_AFTER"], O["Z_AFTER"]
    OT, OH, OK1, OK2 = O["T"], O["H"], O["K1"], O["K2"]
    tail_s = np.where(sr == 0, OT[so], np.where(z_after[so], OK1[so], OT[so]))
    head_s = np.where(sr == 0, np.where(x_after[so], OK2[so], OH[so]), OH[so])
    # ... and from the end vertex (the edge is 'before' there): must agree
    tail_e = np.where(er == 0, OT[eo], np.where(z_after[eo], OT[eo], OK1[eo]))
    head_e = np.where(er == 0, np.where(x_after[eo], OH[eo], OK2[eo]), OH[eo])
    bad = np.nonzero((tail_s != tail_e) | (head_s != head_e))[0]
    if bad.size:
        kk = st["s_cur"][p[bad[0]]] // 2
        raise ViscxError(f"inconsistent visibility complex along the tangency curve of {scene.names[kk]!r} "
                         "(a degenerate configuration, e.g. edges of three objects on one line); "
                         "rebuild with --perturb (Scene.perturbed())")
    th0 = st["s_th"][p]
    th1 = np.where(q <= p, st["s_th"][q] + TWO_PI, st["s_th"][q])  # wrap (also a one-vertex loop)
    j0 = np.where(sr == 0, O["J1"][so], O["J2"][so])
    j1 = np.where(er == 0, O["J1"][eo], O["J2"][eo])
    return th0, th1, tail_s, head_s, j0, j1


def vertex_edges(O, st, occ):
    """The four edges (sorted positions) at occurrences occ: X, Y on K1's curve (X the one
    bounding (T, K2)), Z, W on K2's (Z bounding (K1, H)); and (before, after) on each curve."""
    n_occ = O["K1"].shape[0]
    e1a = st["posof"][occ]; e1b = st["prv"][e1a]
    e2a = st["posof"][occ + n_occ]; e2b = st["prv"][e2a]
    xa, za = O["X_AFTER"][occ], O["Z_AFTER"][occ]
    X = np.where(xa, e1a, e1b); Y = np.where(xa, e1b, e1a)
    Z = np.where(za, e2a, e2b); W = np.where(za, e2b, e2a)
    return X, Y, Z, W, (e1b, e1a, e2b, e2a)


def glue_pairs(X, Y, Z, W):
    """Slot pairs (3·edge + slot) glued at vertices whose four edges are X, Y, Z, W: a vertex
    (k1, k2; t, h) shares (t,k1), (k1,k2), (t,k2), (k1,h), (t,h), (k2,h) among its edges."""
    S = lambda e, s: 3 * e + s  # noqa: E731
    ua = np.concatenate([S(X, 0), S(X, 1), S(X, 2), S(Y, 1), S(Y, 2), S(Z, 1)])
    ub = np.concatenate([S(Y, 0), S(Z, 0), S(W, 0), S(Z, 2), S(W, 2), S(W, 1)])
    return ua, ub


def six_faces(O, comp, occ, X, Y, Z, signs=True):
    """The six faces (components) of occurrences occ and the vertex's role on each.  Near the
    bitangent, (T,K1) is every line crossing K1 and (K2,H) every line crossing K2: the vertex
    is a smooth point of their boundary (sign 0).  The other four faces fill the four sectors
    of the crossing of the two tangency curves: 'both' (K1,K2), 'neither' (T,H), 'K1 only'
    (K1,H), 'K2 only' (T,K2).  When the two sides agree (outer bitangent), 'both' and
    'neither' are the up/down sectors (a chain vertex, −d_e) and the two others the
    left/right ones (an extremal vertex, +d_e); inner bitangents swap them.

    Returns six (k, 6) int64 ((t,k1), (k1,k2), (t,k2), (k1,h), (t,h), (k2,h)), sgn (k, 6) int8
    (None without ``signs``)."""
    c3 = comp.reshape(-1, 3)
    six = np.concatenate([np.take(c3, X, axis=0), np.take(c3, Y, axis=0)[:, 1:], np.take(c3, Z, axis=0)[:, 1:2]],
                         1).reshape(-1, 6)
    if not signs:
        return six, None
    same = O["S1"][occ] == O["S2"][occ]
    zero = np.zeros_like(same)
    a, b = np.where(same, -1, 1), np.where(same, 1, -1)
    sgn = np.stack([zero, a, b, b, a, zero], 1).astype(np.int8).reshape(-1, 6)
    return six, sgn


def slot_faces(st, slots):
    """Tail, head and 'face below the edge' (the edge is on the face's upper chain) of slots.
    Above a curve of side L lie the lines crossing k (slots (t,k), (k,h)); above a curve of
    side R the lines missing it (slot (t,h))."""
    e, kind = slots // 3, slots % 3
    obj, side = st["s_cur"][e] // 2, st["s_cur"][e] % 2
    tail = np.where(kind == SLOT_KH, obj, st["tail"][e])
    head = np.where(kind == SLOT_TK, obj, st["head"][e])
    crossing = kind != SLOT_TH
    below = np.where(side == R, crossing, ~crossing)
    return tail, head, below


def face_sums(O, st, slots, lab, nlab, six, sgn, occ):
    """Dual area (method a), string sum (method b) and boundedness of faces ``0..nlab-1``
    from their slots (ascending, labels ``lab``) and the six faces ``six`` (labels, −1 for
    faces not summed here) of occurrences ``occ`` (ascending).

    Method (a): Green's theorem in the (θ, u) plane, area = ∫ upper u dθ − ∫ lower u dθ.
    Method (b): Orti et al. §4.1: + d_c for edges on the face's own objects, − d_c for the
    others; + d_e for extremal vertices (where the two chains meet), − d_e otherwise.
    Both are summed in slot then occurrence order, so a face gets bit-identical sums
    whichever set of faces is summed with it."""
    e, kind = slots // 3, slots % 3
    _, _, below = slot_faces(st, slots)
    crossing = kind != SLOT_TH
    area = np.bincount(lab, weights=np.where(below, st["I"][e], -st["I"][e]), minlength=nlab)
    strings = np.bincount(lab, weights=np.where(crossing, st["arc"][e], -st["arc"][e]), minlength=nlab)
    live = six.ravel() >= 0
    w = (sgn * O["LEN"][occ][:, None]).ravel().astype(float)
    strings += np.bincount(six.ravel()[live], weights=w[live], minlength=nlab)
    has_up = np.bincount(lab, weights=below.astype(float), minlength=nlab) > 0
    has_lo = np.bincount(lab, weights=(~below).astype(float), minlength=nlab) > 0
    bounded = has_up & has_lo
    return np.where(bounded, area, np.inf), np.where(bounded, strings, np.inf), bounded


def slot_hashes(scene, st, slots, lab, nlab):
    """(nlab,) uint64 signature of each face: the sum of its boundary slots' digests
    (object geometry, side, slot, tail and head, and the exact θ range of the edge).  Tail
    and head enter by their names' digests, not their indices: removing or inserting
    another object (a renumbering) keeps every other face's signature."""
    e, kind = slots // 3, slots % 3
    h = _mix(scene.object_hashes()[st["s_cur"][e] // 2] ^ np.uint64(0x9E3779B97F4A7C15))
    ends = np.append(scene.name_hashes(), np.uint64(7)).view(np.int64)  # [-1]: the sky
    with np.errstate(over="ignore"):
        for part in ((st["s_cur"][e] % 2) * 3 + kind, ends[st["tail"][e]] + 7, ends[st["head"][e]] + 11,
                     st["th0"][e].view(np.int64), st["th1"][e].view(np.int64)):
            h = _mix(h ^ part.astype(np.int64).view(np.uint64))
        acc = np.zeros(nlab, np.uint64)
        np.add.at(acc, lab, h)
    return _mix(acc)


def twin_slots(O, st, slots):
    """The twin of each slot: the reversal (θ, u) → (θ + π, −u) maps the edge starting at
    incidence (occ, role) to the one starting at ((occ + m) mod 2m, 1 − role), and slots
    (t,k), (k,h), (t,h) to (k,h), (t,k), (t,h)."""
    n_occ = O["K1"].shape[0]
    e = slots // 3
    occ = st["s_occ"][e]
    occ = np.where(occ >= n_occ // 2, occ - n_occ // 2, occ + n_occ // 2)
    et = st["posof"][occ + (1 - st["s_role"][e]) * n_occ]
    return 3 * et + np.array([1, 0, 2])[slots % 3]


def face_edge_order(slots, face, th0, below):
    """Order of the boundary slots of faces: by face, upper chain first, by θ0 (mod 2π), then slot."""
    return np.lexsort((th0 % TWO_PI, ~below, face))


def derive(scene: Scene, V: dict):
    """Edges, faces, incidences, dual areas and string sums from the vertices.

    Pure numpy over flat arrays (sorting and a union–find by connected components).
    Returns (arrays, state): the stored arrays and the internal state that
    :func:`viscx.flatland.dynamic.move` updates locally."""
    m = V["v_key"].shape[0]
    if m == 0:
        return _derive_lone(scene), None
    O = occurrences(V)
    n_occ = 2 * m
    cur, th_, tau_, occ_, role_ = incidences(O)
    # vertices of one resolved degenerate line share θ; their infinitesimal offsets order them
    # (and at contacts, the θ of the opened scene orders the vertices: close_contacts)
    ths_ = np.concatenate([O["THS"], O["THS"]])
    order = np.lexsort((occ_, tau_, ths_, cur))
    st = dict(s_occ=occ_[order], s_role=role_[order], s_cur=cur[order], s_th=th_[order], s_tau=tau_[order])
    if "v_theta_sort" in V:  # the update merges new incidences in by it
        st["s_ths"] = ths_[order]
    link(st, n_occ)
    pos = np.arange(order.shape[0])
    edge_attributes(scene, O, st, pos, st)
    # -- faces: union of slots (3·edge + slot) glued at the vertices
    occ = np.arange(n_occ)
    X, Y, Z, W, _ = vertex_edges(O, st, occ)
    ua, ub = glue_pairs(X, Y, Z, W)
    nslot = 3 * pos.shape[0]
    g = coo_matrix((np.ones(ua.shape[0]), (ua, ub)), shape=(nslot, nslot))
    ncomp, comp = connected_components(g, directed=False)
    st["comp"] = comp.astype(np.int64)
    slots = np.arange(nslot)
    six, sgn = six_faces(O, st["comp"], occ, X, Y, Z)
    comp_attributes(scene, O, st, slots, st["comp"], ncomp, six, sgn, occ, st)
    return canonical(scene, V, O, st, np.arange(ncomp), slots, occ), st


def link(st, n_occ):
    """Next / previous incidence on each curve and the sorted position of every incidence."""
    st["nxt"], st["prv"], st["posof"] = K.curve_links(st["s_cur"], st["s_occ"] + st["s_role"] * n_occ)


def edge_attributes(scene, O, st, p, out):
    """Tail, head, θ range, ∫u dθ (method a) and contact arc length d_c (method b) of the
    edges at sorted positions p, into ``out`` (keys tail, head, th0, th1, I, arc)."""
    th0, th1, out["tail"], out["head"], j0, j1 = edge_labels(scene, O, st, p)
    out["th0"], out["th1"] = th0, th1
    A_, cumG, cumS, perim = scene.pieces()
    out["I"], out["arc"] = K.edge_integrals(st["s_cur"][p] // 2, st["s_cur"][p] % 2, th0, th1, scene.vert_start,
                                            scene.verts, scene.radius, A_, cumG, cumS, perim, j0, j1)


def comp_attributes(scene, O, st, slots, lab, nlab, six, sgn, occ, out):
    """Tail, head, twin, smallest slot, sums and signatures of components ``0..nlab-1``
    (their slots ``slots`` ascending with labels ``lab``; ``six`` the labels of the six
    faces of occurrences ``occ``, −1 for faces of other components), written to ``out`` as
    c_* arrays (twins as labels of ``st["comp"]``)."""
    tail, head, _ = slot_faces(st, slots)
    out["c_tail"] = np.full(nlab, -3, np.int64); out["c_tail"][lab] = tail
    out["c_head"] = np.full(nlab, -3, np.int64); out["c_head"][lab] = head
    out["c_twin"] = np.empty(nlab, np.int64); out["c_twin"][lab] = st["comp"][twin_slots(O, st, slots)]
    out["c_minslot"] = np.full(nlab, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(out["c_minslot"], lab, slots)
    out["c_area"], out["c_strings"], out["c_bounded"] = face_sums(O, st, slots, lab, nlab, six, sgn, occ)
    out["c_hash"] = slot_hashes(scene, st, slots, lab, nlab)


def canonical(scene, V, O, st, fresh, new_slots, new_occ):
    """The stored arrays of a state: edges starting at an o = 0 occurrence, in order; faces
    the components oriented from the smaller object id (or from their smaller slot when
    tail = head), sorted by (tail, head, smallest slot).

    The faces' boundary lists are spliced: ``st["face_label"]`` (components in face
    order), ``st["fe_*"]`` and ``st["fv_*"]`` hold the kept faces (renumbered by the
    caller; none the first time), and the components ``fresh`` — whose slots are among
    ``new_slots`` and whose vertices among the occurrences ``new_occ`` (both ascending) —
    are added; ``st`` is updated in place."""
    n = scene.n
    m = V["v_key"].shape[0]
    N = st["s_occ"].shape[0]
    ct, ch, twin, minslot = st["c_tail"], st["c_head"], st["c_twin"], st["c_minslot"]
    # -- faces: kept ones in their order, the fresh representatives merged in by key
    canon_c = np.where(ct != ch, ct < ch, minslot <= minslot[twin])
    key = ((ct + 1) * (n + 1) + (ch + 1)) * (3 * N + 1) + minslot
    fresh = fresh[canon_c[fresh]]
    fresh = fresh[np.argsort(key[fresh], kind="stable")]
    kept = st.get("face_label", np.zeros(0, np.int64))
    F = kept.size + fresh.size
    is_new = np.zeros(F, bool)
    is_new[np.searchsorted(key[kept], key[fresh]) + np.arange(fresh.size)] = True
    rep = np.empty(F, np.int64)
    rep[is_new] = fresh
    rep[~is_new] = kept
    f_new = np.full(ct.shape[0], -1, np.int64)
    f_new[rep] = np.arange(F)
    f_new[twin[rep]] = np.arange(F)
    # -- edges: canonical ones start at an o = 0 occurrence
    e_canon = st["s_occ"] < m
    ce = np.nonzero(e_canon)[0]
    # the others are the twins (twin_slots) of the canonical ones: position of occurrence
    # (occ + m, 1 − role), numbered like them
    e_new = np.empty(N, np.int64)
    e_new[ce] = np.arange(ce.size)
    e_new[st["posof"][st["s_occ"][ce] + m + (1 - st["s_role"][ce]) * 2 * m]] = np.arange(ce.size)
    comp = st["comp"]
    out = {}
    out["e_obj"] = (st["s_cur"][ce] // 2).astype(np.int64)
    out["e_side"] = (st["s_cur"][ce] % 2).astype(np.int8)
    out["e_tail"] = st["tail"][ce]
    out["e_head"] = st["head"][ce]
    end = st["s_occ"][st["nxt"][ce]]
    out["e_verts"] = np.stack([st["s_occ"][ce], np.where(end >= m, end - m, end)], 1).astype(np.int64)
    out["e_theta"] = np.stack([st["th0"][ce], st["th1"][ce]], 1)
    out["e_integral"] = st["I"][ce]
    out["e_arclength"] = st["arc"][ce]
    out["e_faces"] = f_new[np.take(comp.reshape(-1, 3), ce, axis=0)]
    # -- vertex incidences (occurrence o = 0)
    out["v_edges"], out["v_faces"] = K.vertex_incidences(st["posof"], st["prv"], O["X_AFTER"], O["Z_AFTER"], comp,
                                                         e_new, f_new, m)
    # -- faces
    out["f_pair"] = np.stack([ct[rep], ch[rep]], 1)
    out["f_area"] = st["c_area"][rep]
    out["f_strings"] = st["c_strings"][rep]
    out["f_bounded"] = st["c_bounded"][rep]
    # boundary chains of the representatives: their slots, upper chain first, by θ0
    is_fresh = np.zeros(ct.shape[0], bool)
    is_fresh[fresh] = True
    sl = new_slots[is_fresh[comp[new_slots]]]
    _, _, below = slot_faces(st, sl)
    o = np.lexsort((st["th0"][sl // 3] % TWO_PI, ~below, f_new[comp[sl]]))
    # packed as edge << 2 | upper << 1 | reversed (both stay with the edge while it exists)
    packed = (sl[o] // 3) << 2 | below[o].astype(np.int64) << 1 | ~e_canon[sl[o] // 3]
    st["fe_start"], fe = _splice_lists(is_new, st.get("fe_start"), st.get("fe_packed"), f_new[comp[sl[o]]], packed)
    st["fe_packed"] = fe
    out["f_edge_start"] = st["fe_start"]
    out["f_edge"] = e_new[fe >> 2]
    out["f_edge_upper"] = (fe & 2) > 0
    out["f_edge_reversed"] = (fe & 1) > 0
    # boundary vertices of the representatives, with their role (extremal / chain / smooth)
    six, sgn = six_faces(O, comp, new_occ, *vertex_edges(O, st, new_occ)[:3])
    hit = is_fresh[six.ravel()]
    fv_occ = np.repeat(new_occ, 6)[hit]
    ff = f_new[six.ravel()[hit]]
    # packed as vertex << 3 | o << 2 | sign + 1
    packed = (fv_occ % m) << 3 | (fv_occ >= m).astype(np.int64) << 2 | sgn.ravel()[hit] + 1
    o = np.lexsort((fv_occ % m, ff))
    st["fv_start"], fv = _splice_lists(is_new, st.get("fv_start"), st.get("fv_packed"), ff[o], packed[o])
    st["fv_packed"] = fv
    out["f_vert_start"] = st["fv_start"]
    out["f_vert"] = fv >> 3
    out["f_vert_sign"] = ((fv & 3) - 1).astype(np.int8)
    # oriented areas of both twins (for the reciprocity check)
    out["f_area_twin"] = st["c_area"][twin[rep]]
    out["f_strings_twin"] = st["c_strings"][twin[rep]]
    out["f_hash"] = st["c_hash"][rep]
    out["f_hash_twin"] = st["c_hash"][twin[rep]]
    st["face_label"] = rep
    # form factors F_ab = A_ab / (2 L_a), last column: the sky
    out.update(form_factors(scene, out["f_pair"], out["f_area"], out["f_bounded"], out["f_strings"]))
    return out


def _splice_lists(is_new, old_start, old_vals, new_face, new_vals):
    """CSR lists of F faces (``is_new`` (F,) bool in face order): the kept faces' lists from
    (old_start, old_vals) in order, the new faces' from new_vals grouped by their face id
    ``new_face`` (ascending).  Returns (start (F + 1,), values)."""
    F = is_new.shape[0]
    old_start = np.zeros(1, np.int64) if old_start is None else old_start
    old_vals = np.zeros(0, np.int64) if old_vals is None else old_vals
    F_old = old_start.shape[0] - 1
    fid = np.nonzero(is_new)[0]
    # one CSR of the kept lists (rows 0..F_old − 1) then the new ones (rows F_old + i)
    length = np.bincount(new_face, minlength=F)[fid]
    pool_start = np.concatenate([old_start, old_start[-1] + np.cumsum(length)]).astype(np.int64)
    rows = np.empty(F, np.int64)
    rows[~is_new] = np.arange(F_old)
    rows[fid] = F_old + np.arange(fid.size)
    pool = np.concatenate([old_vals[:old_start[-1]], new_vals]).astype(np.int64)
    return K.csr_rows(pool_start, pool, rows, np.zeros(0, np.int64), 0)


def _derive_lone(scene):
    """The complex of a scene of one object: no vertex; its two tangency curves are loops
    (θ ∈ [0, 2π]) with the sky at both ends; faces: the lines missing it (unbounded) and
    the lines crossing it (sky → object, dual area 2 L)."""
    A_, cumG, cumS, perim = scene.pieces()
    obj, side = np.zeros(2, np.int64), np.array([L, R])
    th0, th1 = np.zeros(2), np.full(2, TWO_PI)
    I, arc = K.edge_integrals(obj, side, th0, th1, scene.vert_start, scene.verts, scene.radius, A_, cumG, cumS,
                              perim, np.full(2, -1), np.full(2, -1))
    st = dict(s_cur=side, tail=np.full(2, SKY), head=np.full(2, SKY), th0=th0, th1=th1)
    # slots 0..2 on the L loop, 3..5 on the R loop, glued (t,k) to (t,k) and (k,h) to (k,h):
    # components A = sky → 0, B = 0 → sky (its twin), C / D = (sky, sky) on the L / R loop
    h = slot_hashes(scene, st, np.arange(6), np.array([0, 1, 2, 0, 1, 3]), 4)
    area = I[1] - I[0]  # Green: above λ (L loop, lower chain) and below μ (R loop, upper)
    out = dict(e_obj=np.zeros(1, np.int64), e_side=np.array([R], np.int8), e_tail=np.full(1, SKY),
               e_head=np.full(1, SKY), e_verts=np.full((1, 2), -1, np.int64), e_theta=np.array([[0.0, TWO_PI]]),
               e_integral=I[1:], e_arclength=arc[1:], e_faces=np.array([[1, 1, 0]]),
               v_edges=np.zeros((0, 4), np.int64), v_faces=np.zeros((0, 6), np.int64),
               f_pair=np.array([[SKY, SKY], [SKY, 0]]), f_area=np.array([np.inf, area]),
               f_strings=np.array([np.inf, arc[1] + arc[0]]), f_bounded=np.array([False, True]),
               f_edge_start=np.array([0, 1, 3]), f_edge=np.zeros(3, np.int64),
               f_edge_upper=np.array([True, True, False]), f_edge_reversed=np.array([True, False, True]),
               f_vert_start=np.zeros(3, np.int64), f_vert=np.zeros(0, np.int64), f_vert_sign=np.zeros(0, np.int8),
               f_hash=h[[2, 0]], f_hash_twin=h[[3, 1]])
    out["f_area_twin"], out["f_strings_twin"] = out["f_area"].copy(), out["f_strings"].copy()
    out.update(form_factors(scene, out["f_pair"], out["f_area"], out["f_bounded"], out["f_strings"]))
    return out


def _mix(x):
    """splitmix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    x = x.astype(np.uint64)
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def form_factors(scene, f_pair, f_area, f_bounded, f_strings):
    """F_area, F_strings (n, n + 1): F_ab = Σ_faces{a,b} A / (2 L_a); column n is the sky.
    (One bincount over both orientations: the same sequential sums as adding them in
    face order.)"""
    n = scene.n
    Lp = scene.perimeters()
    out = {}
    a, b = f_pair[:, 0], f_pair[:, 1]
    ok = f_bounded & ((a >= 0) | (b >= 0))
    a, b = a[ok], b[ok]
    ai = np.where(a < 0, n, a); bi = np.where(b < 0, n, b)
    m1, m2 = a >= 0, b >= 0
    cell = np.concatenate([a[m1] * (n + 1) + bi[m1], b[m2] * (n + 1) + ai[m2]])
    for name, val in (("F_area", f_area), ("F_strings", f_strings)):
        v = val[ok]
        w = np.concatenate([v[m1] / (2.0 * Lp[a[m1]]), v[m2] / (2.0 * Lp[b[m2]])])
        out[name] = np.bincount(cell, weights=w, minlength=n * (n + 1)).reshape(n, n + 1)
    return out


def blocker_table(scene: Scene, cand: dict, cls) -> np.ndarray:
    """(4 n²,) int32 indexed by candidate key: an object blocking the candidate's segment
    (−1: free).  A blocked candidate can only become free when its blocker moves."""
    table = np.full(4 * scene.n * scene.n, -1, np.int32)
    table[cand["key"]] = cls[6]
    return table


def build(scene: Scene, eps: float | None = None, quiet: bool = True) -> FlatComplex:
    """Build the visibility complex of ``scene`` (and its form factors)."""
    from viscx.progress import bar

    eps = default_eps(scene) if eps is None else float(eps)
    with bar(total=3, desc="flatland complex", quiet=quiet, unit="stage") as pb:
        # touching objects: the vertices of the opened scene (every contact a small gap),
        # carried back to the scene as the limit of the closing gap (close_contacts)
        for attempt, rel in enumerate(OPEN_RELS if scene.contacts().size else (0.0,)):
            opened = scene.opened(rel) if rel else scene
            try:
                cand = candidates(opened)
                cls = classify(opened, cand, eps)
                V = resolve_degenerate(opened, vertices_from(opened, cand, cls))
                pb.update(2)
                if opened is not scene:
                    V = close_contacts(scene, V)
                out, state = derive(scene, V)
                if state is not None and opened is not scene:  # the update re-tests its zone there
                    opened._contacts = np.zeros((0, 2), np.int64)
                    state["open"] = (rel, opened)
                break
            except ViscxError:
                # a line between the two sides of an opened contact is known to ~ulp(x)/γ
                # in direction: near the 1e-9 line tolerance in a large scene, the opened
                # scene may be unresolvable at one γ and not at another (tried in order)
                if attempt + 1 == len(OPEN_RELS) or not rel:
                    raise
        V.update(out)
        pb.update()
    return FlatComplex(scene=scene, eps=eps, arrays=V, state=state, blockers=blocker_table(scene, cand, cls))


def close_contacts(scene: Scene, V: dict) -> dict:
    """The vertices of the opened scene (:meth:`Scene.opened`) carried to ``scene``: the
    complex of touching objects as the limit of a closing gap.

    Each vertex keeps what the opened scene decided — its objects, sides, support points,
    tail and head, and its place along the tangency curves, ``v_theta_sort`` (the opened
    θ, with ``v_tau``; :func:`derive` sorts by it) — and takes its line from the scene
    itself: the common tangent of its two support disks (v_j, r) on their sides,
    n(θ)·(v_2 − v_1) = σ_1 r_1 − σ_2 r_2, the root nearest the opened θ (closed form as in
    :func:`kernels.pair_bitangents`; when both support points coincide — two corners
    touching — the line through them keeps the opened direction, the direction in which
    the gap closes).  As the gap closes nothing changes but these lines (no vertex
    appears or vanishes: the opened scene differs from the scene by γ only near the
    contacts, where the vertices converge), so dual areas summed with the limit θ's in
    the opened order are the limits of the opened scene's: the form factors of the
    touching objects, where the lines through a contact of measure 0 go from one object
    straight into the other (contact faces see each other)."""
    V = dict(V)
    ths = V["v_theta"]
    k1, k2 = V["v_obj"][:, 0], V["v_obj"][:, 1]
    j1, j2 = V["v_support"][:, 0], V["v_support"][:, 1]
    sg1 = 2.0 * V["v_side"][:, 0] - 1.0
    sg2 = 2.0 * V["v_side"][:, 1] - 1.0
    r1, r2 = sg1 * scene.radius[k1], sg2 * scene.radius[k2]
    w = scene.verts[j2] - scene.verts[j1]
    wn = np.hypot(w[:, 0], w[:, 1])
    d1, d2 = (np.mod(t - ths + math.pi, TWO_PI) - math.pi for t in K.sine_roots(w, r1 - r2))
    th = np.where(wn > 0, ths + np.where(np.abs(d1) <= np.abs(d2), d1, d2), ths)
    d = np.stack([np.cos(th), np.sin(th)], 1)
    nrm = np.stack([-d[:, 1], d[:, 0]], 1)
    p = scene.verts[j1] + r1[:, None] * nrm
    q = scene.verts[j2] + r2[:, None] * nrm
    # the maximal free segment ends where the line meets its tail / head in the scene: the
    # boundary point of that object on the line nearest the opened end (γ away)
    seg = V["v_seg"]
    ends = []
    for e, x, end in ((V["v_tail"], p, seg[:, :2]), (V["v_head"], q, seg[:, 2:])):
        pt = x + np.einsum("ij,ij->i", end - x, d)[:, None] * d
        on = e >= 0
        pt[on] += boundary_hits(scene, e[on], pt[on], d[on])[:, None] * d[on]
        ends.append(pt)
    seg = clip_sky_ends(scene, th, p, q, V["v_tail"], V["v_head"], np.concatenate(ends, 1))
    V.update(v_theta_sort=ths, v_theta=th, v_p=p, v_q=q, v_length=np.einsum("ij,ij->i", q - p, d), v_seg=seg)
    return V


def boundary_hits(scene: Scene, obj, o, d):
    """(N,) t of the point o + t d of object obj's boundary nearest o (0 if the line misses
    it): o (N, 2) points, d (N, 2) unit directions.  Polygons: the line's crossings of the
    edges and the corners on it (within the line tolerance); circles: both crossings (a
    tangent line: the tangent point)."""
    t = np.zeros(obj.shape[0])
    tol = line_tol(scene)
    for k in np.unique(obj):
        rows = np.nonzero(obj == k)[0]
        v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
        oo, dd = o[rows], d[rows]
        if scene.radius[k] > 0:
            w = v[0] - oo
            b = np.einsum("ij,ij->i", w, dd)
            h = np.sqrt(np.maximum(scene.radius[k] ** 2 - (np.einsum("ij,ij->i", w, w) - b * b), 0.0))
            cand = np.stack([b - h, b + h], 1)
        else:
            w = v[None, :, :] - oo[:, None, :]                                   # (R, m, 2)
            off = w[:, :, 0] * dd[:, None, 1] - w[:, :, 1] * dd[:, None, 0]      # signed distances
            along = w[:, :, 0] * dd[:, None, 0] + w[:, :, 1] * dd[:, None, 1]
            corner = np.where(np.abs(off) <= tol, along, np.inf)
            o2, a2 = np.roll(off, -1, axis=1), np.roll(along, -1, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                f = off / (off - o2)
            cross = np.where((off * o2 < 0) & np.isfinite(f), along + f * (a2 - along), np.inf)
            cand = np.concatenate([corner, cross], 1)
        j = np.argmin(np.abs(cand), axis=1)
        best = cand[np.arange(rows.size), j]
        t[rows] = np.where(np.isfinite(best), best, 0.0)
    return t
