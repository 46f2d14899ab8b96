"""Output-sensitive V0: candidate lines for the nodes, far fewer than all tuples.

:func:`fast_candidates` proposes candidate lines in the same form as
:func:`viscx.skeleton.reference.reference_candidates` (same canonical generator
tuples, same line constructions, so the same floats), but only for tuples that
can still be nodes; :func:`build_nodes` hands them to
:func:`viscx.skeleton.nodes.validate_candidates`, the one definition of a node.
The result equals :func:`viscx.skeleton.reference.reference_nodes` exactly as
long as every node's tuple is proposed: the candidate set is a superset of the
nodes' tuples, and validation decides each candidate on its own.

What a node guarantees (docs/skeleton.md)
-----------------------------------------
Let a node's generator points, sorted along its line ℓ, be g₁ … g_k. Validation
accepts it only if

(N1) ℓ passes within ε of every generator, edge points are the points of the
     edge's line closest to ℓ and lie strictly inside the edge (x·|e| > ε and
     (1 - x)·|e| > ε), consecutive points are more than ε apart along ℓ;
(N2) inner points g₂ … g_{k-1} are passing (tangent, not grazing a foreign face);
(N3) every piece [gᵢ, gᵢ₊₁], trimmed by ε at both ends, is free for the ray caster.

Enumeration: every generator lies in the hull of the outer two
----------------------------------------------------------------------
The projections of g₂ … g_{k-1} on ℓ lie between those of g₁ and g_k, and each
gᵢ is within ε of ℓ, so every inner gᵢ is within 2ε of the segment [g₁, g_k]
(write ĝ for the projection: gᵢ - ((1-λ)g₁ + λg_k) = rᵢ - (1-λ)r₁ - λr_k, each
|r| ≤ ε). [g₁, g_k] joins a point of the first generator to a point of the last,
so it lies in their convex hull: the tetrahedron conv(a ∪ d) of two edges, the
triangle conv(v ∪ e) of a vertex and an edge. Hence, with H the hull inflated
by ``HULL_TOL`` ε (≥ 2ε plus rounding):

* E4 (a, b, c, d) with outer edges a, d: b and c meet H(a, d);
* VEE with the vertex inner (e₁, v, e₂): v lies in H(e₁, e₂);
* VEE with the vertex at an end (v, e₁, e₂): e₁ meets H(v, e₂);
* VV: the only pair.

So the builder visits pairs (edge, edge) and (vertex, edge) and asks a uniform
grid of generator edges and vertices which of them meet the inflated hull
(separating axes: the normals of the hull's faces and, in each face, of its
sides; any subset of the axes of an exact test is conservative, degenerate axes
are skipped). Edges sharing an endpoint are never two generators of one node
(the line through both meets them at the shared endpoint, which (N1) rejects,
or it is not unique); the reference enumerates those tuples and validation
rejects them, so they are not proposed.

Pruning: isolated convex solids block whole families of segments
-------------------------------------------------------------------
A *blocking solid* C is a connected component of the scene (faces joined by
shared vertices) that is a closed 2-manifold whose every vertex lies on the
inner side of every one of its face planes (a convex polytope bounded by
exactly those faces), and that is *isolated*: every generator edge of another
component stays farther than ``ISOLATION`` ε from C (tested against C's face
planes pushed out by that much, which contains C's ε-neighbourhood).
C_in is C scaled about its centroid so that every face plane moves inwards by at
least ``SOLID_DEPTH`` ε: points of C_in are that deep inside C.

Lemma 1 (corners suffice). For a convex set K, if the four segments joining the
endpoints of edge a to those of edge d meet K, every segment joining a point of
a to a point of d meets K. Proof: for a point p, {x : [p, x] meets K} =
{p + λ(k - p) : k ∈ K, λ ≥ 1} is convex, so along a line the blocked
parameters form an interval. Fix t = 0: the blocked s on a form an interval
holding 0 and 1, so all of [0, 1]; likewise for t = 1; then for each s the
blocked t form an interval holding 0 and 1. For a vertex and an edge, the two
segments from the vertex to the edge's endpoints suffice (same argument).

Lemma 2 (no node crosses a solid). Let two generators X, Y of a node lie in
other components than C, and let every segment joining X to Y meet C_in. Then
the tuple is not a node. Proof: by isolation X and Y are outside C (they are
more than ``ISOLATION`` ε from C and not inside it, since a generator inside C
would make C non-isolated), while [g_X, g_Y] ⊂ [g₁, g_k] reaches depth
``SOLID_DEPTH`` ε inside C: ℓ crosses ∂C at some point Z of [g₁, g_k] with
[Z, deeper point] inside C. A generator point on one of C's own edges is not
inner (a line passing a convex polytope's edge lies in a supporting plane, and a
line grazing one of its faces stays within 1e-9 rad of a supporting plane: it
cannot reach that depth), and not an end (ends are X, Y's side: they lie outside
C). Every other generator point is farther than ``ISOLATION`` ε > ε from ∂C, so
Z lies inside a trimmed piece of (N3), which crosses C's surface from outside
to a depth of ``SOLID_DEPTH`` ε: the ray caster reports that face (a clear
crossing at an angle of at least depth / diagonal, far above the float32 limits
of :mod:`viscx.raycast`), and the piece is not free.

Any two generators of a node therefore must not be *blocked*: for a pair of
generator vertices, the segment joining them meets C_in (found by casting rays
against the scaled solids, exact float64 first hits from
:class:`viscx.raycast.RayCaster`), with C foreign to both; for a pair involving
edges, by Lemma 1, all corner segments meet the same C_in. The builder casts
one ray per pair of generator vertices (``blocked_table``) and looks the corners
up. The outer pair of a hull scan (two edges, or a vertex and an edge) is also
tested finer: Lemma 1 on each cell of its (s, t) square split ``HIDDEN_DEPTH``
times (sub-edges are segments too), each cell's four corner segments meeting
one foreign solid's C_in, tested by clipping against its planes
(``_pair_hidden``); different cells may be hidden by different solids. Scenes
without isolated convex solids lose nothing, they just get no pruning.

Exact filters on the line (numba, in the scans)
--------------------------------------------------
Inside the hulls the scans compute the line itself by closed forms and keep a
tuple only if that line meets every segment with validation's ε rules (points
more than ε from the edges' ends and from each other), relaxed to
``END_MARGIN`` ε plus ``PARAM_SLACK``: the closed forms and the reference's
constructions agree far better than that wherever the closed forms are well
conditioned, and wherever they are not (a pole, a near double root, dependent
conditions) the filter accepts.

* VEE, v at an end: the lines through v meeting e are v → e(t); the one meeting
  line b has (e(t) - v) · ((b₀ - v) × b') = 0, linear in t.
* VEE, v inside: the line through v meeting lines a and d meets a where a crosses
  the plane through v and d (and vice versa).
* E4: the lines through a(s) and d(t) meet line b where the side product
  f_b(s, t) = α + βs + γt + δst vanishes (bilinear); along b the (s, t) of the
  line through b(u) are linear-fractional in u, so each inner edge's arc has a
  box spanned by its ends (unless it crosses a pole); boxes that miss the square
  or each other are dropped, and for the rest f_b = f_c = 0 is a quadratic in s.
  Eliminating t adds a root where neither f depends on t (γ + δs = 0 for both,
  e.g. s where a meets b while c and d are parallel: the floor's edges and the
  boxes' vertical ones); there a line needs α + βs = 0 for both as well, and
  where one is clearly not zero the root is dropped instead of accepted.

Solids on the line. Where the closed form gives the line, the scans also apply
Lemma 2 to it: when the outer generators (a and d, or v and e) are foreign to a
blocking solid and the segment between their points A, D of the closed form
meets that solid's C_in moved inwards by δ = ``POINT_SLACK`` ε + ``PARAM_SLACK``
times the edge's length, the tuple is not a node. The reference's generator
points A', D' lie within δ of A, D (the accuracy the ε filters above already
assume, and more), so the point of [A', D'] with the same weights as a point
of [A, D] deep inside lies within δ of it, in C_in: Lemma 2 holds for the
reference's line. Where the closed form is ill-conditioned no line is tested.
This leaves about one tuple per candidate (ten times fewer E4 quadruples, half
the VEE triples, on the city of boxes).

Coplanar edges. If b lies in the plane π of a and d (f_b vanishes identically),
the three conditions "meets a, b, d" hold for every line of π, a 3-dimensional
subspace of Plücker space lying wholly in the Plücker quadric; a fourth condition
leaves a pencil of real lines (or dependent conditions), which
``lines_through_four_lines`` reports as degenerate: the reference finds no line.
So b is never an inner edge of (a, d). If a and d are coplanar (parallel or
meeting), every line meeting both at separated points lies in their plane and
meets an inner edge b where b crosses it; when b crosses steeply (sin ≥ 0.1)
within ε/2 of one of its ends (or outside it), that is at b's end, which
validation rejects, so b is dropped as well. More generally, when three of the
four lines are pairwise coplanar (in one plane, or through one point, possibly
at infinity) their conditions hold on a 3-dimensional subspace of real lines
(the lines of the plane, or through the point), and the fourth again leaves a
family or nothing: the pair (b, c) is skipped when b, c and a (or d) are. This is the floor of an
architectural scene: its edges and every box's bottom edges are coplanar, and
every vertical edge meets the floor at its end.

Inner edges are passed
----------------------
(N2) asks every inner generator to be passed. At an inner point of an edge b whose
two faces alone touch it (a clean edge of a mesh), a line is passed iff both faces lie
on one side of the plane through the line and b (:mod:`viscx.geometry.tangency`), which
depends only on the line's direction u projected along b: u⊥ must not lie strictly
between the faces' inward directions w₁, w₂ (perpendicular to b), an arc of the circle
of lines about b (:func:`passing_arcs`). A node's line passes within ε of its outer
generator points A', D' and of B' on b, so u⊥ lies within asin(2ε / |A'⊥|) of the
direction of A'⊥ (A' projected along b, b's line at the origin), and A' lies on the
outer segment: u⊥ lies on the arc of directions in which b's line sees the projected
outer segment, grown by that error (:func:`_sight_arc`), and likewise for D'. An inner
edge whose passing arc, grown by ``PASS_ANGLE``, misses the intersection of the two
sight arcs is dropped (:func:`_passable`; three arcs meet iff one's start lies on the
other two). The growth keeps the dropped directions clearly inside the crossing ones
(at least 1e-7 off each face's plane and off b for a unit direction): validation
calls them crossing whatever its grazing tolerances. On a fine mesh most edges are
nearly flat, so few directions pass them: this is what keeps the bunny's candidates
near its nodes.

VV candidates are the unblocked pairs not joined by an edge whose segment is
free, tested exactly as validation tests it (same two points in the same order
along the canonical direction, so the same rays). VEE and E4 candidates are the
tuples found as above with every pair of generators unblocked, deduplicated,
whose line (computed exactly as the reference does) passes (N1) with doubled
tolerances (2ε distance, ε/2 from the edge ends, ε/2 gaps): a looser copy of
validation's own first test, so rounding cannot drop a node.

Cost: one ray per vertex pair (against the solids only), one hull query per
unblocked pair of generators (grid cells of the hull's box, then a few dot
products per listed edge; the E4 scan takes the vertices in the hull from the
edges found), a closed-form solve per pair of inner edges whose arcs' boxes
meet, and about one tuple per candidate; the hull scans run in numba (nogil) on
a thread per core. At 997 polygons (``random_boxes(997)``): 2 million outer edge
pairs, 1.3 million hull queries, 60 million pairs of inner edges solved, 0.26
million E4 quadruples for 0.24 million E4 candidates; about 17 s of CPU for the
candidates (E4 scan 10, VEE scan 4.5) and 3.6 s for their validation.
"""

import os
import time

import numpy as np
from numba import njit

from viscx.arrays import row_norms, unique_rows
from viscx.geometry.lines import line_through_point_and_two_lines, lines_through_four_lines
from viscx.geometry.vec3 import add as _add, axpy as _axpy, cross as _cross, div as _div, dot as _dot
from viscx.geometry.vec3 import row as _row, row4 as _row4, set_row as _set_row, sub as _sub
from viscx.grid import bin_boxes, cell_of
from viscx.parallel import map_chunks
from viscx.progress import bar
from viscx.skeleton.nodes import E4, VEE, VV, Nodes, canonical_directions, free_pieces, nodes_among, sort_nodes, validate_candidates
from viscx.skeleton.reference import edge_lines
from viscx.tolerances import (
    ANGLE_TOLERANCE,
    COPLANAR,
    END_MARGIN,
    HULL_TOL,
    IN_PLANE,
    ISOLATION,
    PARALLEL_TOLERANCE,
    PARAM_SLACK,
    POINT_SLACK,
    SOLID_DEPTH,
)

#: Largest (faces × vertices) of a component tested for convexity.
CONVEXITY_BUDGET = 4_000_000
#: Rays per call when filling the blocked table.
RAY_CHUNK = 1 << 20
#: Tuples per chunk when solving candidate lines (bounds memory; chunks run on threads).
LINE_CHUNK = 1 << 18
#: Margin (radians) by which a line's direction must lie inside an edge's crossing
#: directions for the scans to drop it as an inner generator (:func:`passing_arcs`).
PASS_ANGLE = 1e-6
#: Candidates per call of the validator (bounds its memory).
VALIDATE_CHUNK = 1 << 18


def _components(scene):
    """Component of each vertex (faces joined through shared vertices)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    he = scene.half_edges
    n = scene.n_vertices
    graph = coo_matrix((np.ones(len(he.start)), (he.start, he.end)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def blocking_solids(scene):
    """The isolated convex closed components, and their copies shrunk inwards.

    Returns
    -------
    solid_of_vertex : (n_vertices,) int
        Blocking solid of each vertex, -1 if none.
    vertices : (k, 3) float
    triangles : (t, 3) int
        The scaled copies C_in (module docstring), triangulated like the scene.
    triangle_solid : (t,) int
    """
    eps, tol = scene.epsilon, 10 * scene.weld_tolerance
    he = scene.half_edges
    comp = _components(scene)
    n_comp = comp.max() + 1
    face_first_vertex = scene.loop_vertices[scene.loop_offsets[scene.face_loop_offsets[:-1]]]
    face_comp = comp[face_first_vertex]
    usable = np.ones(n_comp, dtype=bool)
    # closed 2-manifold: every half-edge has an opposite; faces without holes
    usable[comp[he.start[he.opp < 0]]] = False
    holes = np.diff(scene.face_loop_offsets) > 1
    usable[face_comp[holes]] = False
    # a component without faces (isolated vertices) is not a solid
    has_face = np.zeros(n_comp, dtype=bool)
    has_face[face_comp] = True
    usable &= has_face

    vert_order = np.argsort(comp, kind="stable")
    vert_start = np.searchsorted(comp[vert_order], np.arange(n_comp + 1))
    face_order = np.argsort(face_comp, kind="stable")
    face_start = np.searchsorted(face_comp[face_order], np.arange(n_comp + 1))
    centroid = np.zeros((n_comp, 3))
    np.add.at(centroid, comp, scene.vertices)
    centroid /= np.maximum(np.bincount(comp, minlength=n_comp), 1)[:, None]
    nv_c, nf_c = np.diff(vert_start), np.diff(face_start)
    usable &= nv_c * nf_c <= CONVEXITY_BUDGET

    margin = SOLID_DEPTH * eps
    plane_n, plane_off = np.zeros((len(scene.face_area), 3)), np.zeros(len(scene.face_area))
    scale = np.zeros(n_comp)
    for c in np.flatnonzero(usable):
        faces = face_order[face_start[c] : face_start[c + 1]]
        verts = vert_order[vert_start[c] : vert_start[c + 1]]
        n, off = scene.face_normal[faces], scene.face_offset[faces]
        # orient every plane outwards: the centroid of a convex polytope is inside
        height = off - n @ centroid[c]
        sign = np.where(height >= 0, 1.0, -1.0)
        n, off, height = n * sign[:, None], off * sign, np.abs(height)
        outside = scene.vertices[verts] @ n.T - off[None, :]
        if outside.max() > tol or height.min() <= 4 * margin:
            usable[c] = False
            continue
        plane_n[faces], plane_off[faces] = n, off
        scale[c] = 1.0 - margin / height.min()

    # isolation: no generator edge of another component near the solid
    ge = scene.generator_edges
    ev = he.edge_vertices[ge]
    usable = _isolated(
        usable,
        scene.vertices,
        ev,
        comp,
        face_order,
        face_start,
        plane_n,
        plane_off,
        ISOLATION * eps,
    )
    solid_of_vertex = np.where(usable[comp], comp, -1)
    tri_comp = face_comp[scene.triangle_face]
    keep = usable[tri_comp]
    tris = scene.triangles[keep]
    tri_solid = tri_comp[keep]
    used, new_tris = np.unique(tris, return_inverse=True)
    c = comp[used]
    verts = centroid[c] + scale[c][:, None] * (scene.vertices[used] - centroid[c])
    return solid_of_vertex, verts, new_tris.reshape(-1, 3).astype(np.int64), tri_solid.astype(np.int64)


@njit(cache=True)
def _isolated(usable, vertices, ev, comp, face_order, face_start, plane_n, plane_off, gap):
    """Clear ``usable`` for solids that another component's generator edge comes near."""
    out = usable.copy()
    n_comp = usable.shape[0]
    lo = np.full((n_comp, 3), np.inf)
    hi = np.full((n_comp, 3), -np.inf)
    for v in range(vertices.shape[0]):
        c = comp[v]
        for k in range(3):
            lo[c, k] = min(lo[c, k], vertices[v, k] - gap)
            hi[c, k] = max(hi[c, k], vertices[v, k] + gap)
    for c in range(n_comp):
        if not usable[c]:
            continue
        for i in range(ev.shape[0]):
            if comp[ev[i, 0]] == c:
                continue
            a = vertices[ev[i, 0]]
            b = vertices[ev[i, 1]]
            apart = False
            for k in range(3):
                if max(a[k], b[k]) < lo[c, k] or min(a[k], b[k]) > hi[c, k]:
                    apart = True
            if apart:
                continue
            # clip the segment by the solid's planes pushed out by ``gap``
            t0, t1 = 0.0, 1.0
            for j in range(face_start[c], face_start[c + 1]):
                f = face_order[j]
                fa = plane_n[f, 0] * a[0] + plane_n[f, 1] * a[1] + plane_n[f, 2] * a[2] - plane_off[f] - gap
                fb = plane_n[f, 0] * b[0] + plane_n[f, 1] * b[1] + plane_n[f, 2] * b[2] - plane_off[f] - gap
                if fa > 0 and fb > 0:
                    t0, t1 = 1.0, 0.0
                    break
                if fa > 0:
                    t0 = max(t0, fa / (fa - fb))
                elif fb > 0:
                    t1 = min(t1, fa / (fa - fb))
            if t0 <= t1:
                out[c] = False
                break
    return out


def blocked_table(scene, gv, solids=None):
    """For each pair of generator vertices, the blocking solid whose inner copy their
    segment meets (-1 for none, or when that solid holds one of them).

    Parameters
    ----------
    scene : Scene
    gv : (g,) int
        Generator vertex ids; the table is indexed by position in ``gv``.
    solids : tuple, optional
        :func:`blocking_solids` of the scene, when already computed.

    Returns
    -------
    table : (g, g) int32
        Symmetric.
    solid_of_vertex : (g,) int
    """
    from viscx.raycast import RayCaster

    sov_all, verts, tris, tri_solid = blocking_solids(scene) if solids is None else solids
    sov = sov_all[gv]
    g = len(gv)
    table = np.full((g, g), -1, dtype=np.int32)
    if len(tris) == 0 or g < 2:
        return table, sov
    caster = RayCaster(verts, tris, tri_solid, epsilon=scene.epsilon)
    x = scene.vertices[gv]
    i_all, j_all = np.triu_indices(g, 1)
    for lo in range(0, len(i_all), RAY_CHUNK):
        i, j = i_all[lo : lo + RAY_CHUNK], j_all[lo : lo + RAY_CHUNK]
        vec = x[j] - x[i]
        length = row_norms(vec)
        solid, _ = caster.first_hit(x[i], vec, tmin=0.0, tmax=length)
        # the first solid met may hold an end (a segment into its own solid): look from the other end
        own = (solid >= 0) & ((solid == sov[i]) | (solid == sov[j]))
        if own.any():
            back, _ = caster.first_hit(x[j[own]], -vec[own], tmin=0.0, tmax=length[own])
            solid[own] = back
        foreign = (solid >= 0) & (solid != sov[i]) & (solid != sov[j])
        table[i[foreign], j[foreign]] = solid[foreign]
        table[j[foreign], i[foreign]] = solid[foreign]
    return table, sov


class _SolidGrid:
    """The inner copies C_in of the blocking solids as plane sets, in a uniform grid.

    Parameters
    ----------
    verts : (k, 3) float
    tris : (t, 3) int
    tri_solid : (t,) int
        As returned by :func:`blocking_solids`.
    """

    def __init__(self, verts, tris, tri_solid):
        n_solids = int(tri_solid.max()) + 1 if len(tri_solid) else 0
        # one plane per triangle (a face's triangles repeat its plane: harmless),
        # oriented outwards: the centroid of a convex polytope is inside
        a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
        normal = np.cross(b - a, c - a)
        normal /= row_norms(normal)[:, None]
        centroid = np.zeros((n_solids, 3))
        np.add.at(centroid, tri_solid, (a + b + c) / 3)
        centroid /= np.maximum(np.bincount(tri_solid, minlength=n_solids), 1)[:, None]
        offset = np.einsum("ij,ij->i", normal, a)
        flip = np.einsum("ij,ij->i", normal, centroid[tri_solid]) > offset
        normal[flip], offset[flip] = -normal[flip], -offset[flip]
        order = np.argsort(tri_solid, kind="stable")
        self.plane_offsets = np.searchsorted(tri_solid[order], np.arange(n_solids + 1))
        self.planes = np.ascontiguousarray(np.concatenate([normal, offset[:, None]], axis=1)[order])
        corners = np.stack([a, b, c], axis=1)
        lo_t, hi_t = corners.min(axis=1), corners.max(axis=1)
        box_lo = np.full((n_solids, 3), np.inf)
        box_hi = np.full((n_solids, 3), -np.inf)
        np.minimum.at(box_lo, tri_solid, lo_t)
        np.maximum.at(box_hi, tri_solid, hi_t)
        # solid ids are component ids: only some of them are solids
        present = np.flatnonzero(np.isfinite(box_lo[:, 0]))
        if len(present):
            self.lo, hi = box_lo[present].min(axis=0), box_hi[present].max(axis=0)
        else:
            self.lo, hi = np.zeros(3), np.ones(3)
        span = np.maximum(hi - self.lo, 1e-12)
        side = (np.prod(span) / max(4.0 * len(present), 1.0)) ** (1 / 3)
        self.dims = np.clip(np.ceil(span / side), 1, 256).astype(np.int64)
        self.cell = span / self.dims
        self.offsets, items = bin_boxes(self.lo, self.cell, self.dims, box_lo[present], box_hi[present])
        self.items = present[items]
        self.n_solids = n_solids

    def args(self):
        """The arrays the numba kernels take, in their order."""
        return (self.plane_offsets, self.planes, self.lo, self.cell, self.dims, self.offsets, self.items)


@njit(cache=True, nogil=True)
def _segment_meets_solid(A, B, solid, plane_offsets, planes, margin=0.0):
    """Whether segment AB meets the convex solid (clipped by each of its planes), its
    planes moved inwards by ``margin`` (unit normals: points it then meets lie that
    deep inside)."""
    if plane_offsets[solid] == plane_offsets[solid + 1]:
        return False  # not a solid
    t0, t1 = 0.0, 1.0
    for k in range(plane_offsets[solid], plane_offsets[solid + 1]):
        # offset - 0.0 is the offset exactly: without a margin, the same floats
        offset = planes[k, 3] - margin
        fa = planes[k, 0] * A[0] + planes[k, 1] * A[1] + planes[k, 2] * A[2] - offset
        fb = planes[k, 0] * B[0] + planes[k, 1] * B[1] + planes[k, 2] * B[2] - offset
        if fa > 0 and fb > 0:
            return False
        if fa > 0:
            t0 = max(t0, fa / (fa - fb))
        elif fb > 0:
            t1 = min(t1, fa / (fa - fb))
        if t0 > t1:
            return False
    return True


#: Subdivision levels of the (s, t) square when proving an outer pair hidden.
HIDDEN_DEPTH = 1


@njit(cache=True, nogil=True)
def _pair_hidden(P0, P1, Q0, Q1, split_s, own1, own2, plane_offsets, planes, lo, cell, dims, offsets, items, stamp, counter):
    """Whether every segment from a point of P0P1 to a point of Q0Q1 meets the inner
    copy of a blocking solid other than ``own1`` and ``own2`` (Lemma 1 on the cells
    of a subdivided (s, t) square: each cell's four corner segments meet one solid).
    Conservative: False when that is not shown within HIDDEN_DEPTH levels.

    ``split_s`` is False when P0 = P1 (a vertex). ``stamp`` and ``counter[0]``
    mark solids already tried for the current cell."""
    stack = np.empty((4 * HIDDEN_DEPTH + 4, 5))
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3], stack[0, 4] = 0.0, 1.0, 0.0, 1.0, 0.0
    top = 1
    dP, dQ = _sub(P1, P0), _sub(Q1, Q0)
    small = min(cell[0], min(cell[1], cell[2]))
    while top > 0:
        top -= 1
        s0, s1, t0, t1, depth = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3], stack[top, 4]
        A0, A1, B0, B1 = _axpy(P0, s0, dP), _axpy(P0, s1, dP), _axpy(Q0, t0, dQ), _axpy(Q0, t1, dQ)
        # candidate solids: those listed in the cells along the cell's middle segment
        M, N = _axpy(P0, 0.5 * (s0 + s1), dP), _axpy(Q0, 0.5 * (t0 + t1), dQ)
        MN = _sub(N, M)
        steps = int(np.sqrt(_dot(MN, MN)) / small) + 1
        counter[0] += 1
        hidden = False
        for k in range(steps + 1):
            X = _axpy(M, k / steps, MN)
            c = (cell_of(X[0], lo[0], cell[0], dims[0]) * dims[1] + cell_of(X[1], lo[1], cell[1], dims[1])) * dims[2] + cell_of(
                X[2], lo[2], cell[2], dims[2]
            )
            for j in range(offsets[c], offsets[c + 1]):
                solid = items[j]
                if stamp[solid] == counter[0] or solid == own1 or solid == own2:
                    continue
                stamp[solid] = counter[0]
                if (
                    _segment_meets_solid(A0, B0, solid, plane_offsets, planes)
                    and _segment_meets_solid(A0, B1, solid, plane_offsets, planes)
                    and _segment_meets_solid(A1, B0, solid, plane_offsets, planes)
                    and _segment_meets_solid(A1, B1, solid, plane_offsets, planes)
                ):
                    hidden = True
                    break
            if hidden:
                break
        if hidden:
            continue
        if depth >= HIDDEN_DEPTH:
            return False
        sm, tm = 0.5 * (s0 + s1), 0.5 * (t0 + t1)
        for half_t in range(2):
            ta, tb = (t0, tm) if half_t == 0 else (tm, t1)
            if split_s:
                for half_s in range(2):
                    sa, sb = (s0, sm) if half_s == 0 else (sm, s1)
                    stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3], stack[top, 4] = sa, sb, ta, tb, depth + 1
                    top += 1
            else:
                stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3], stack[top, 4] = s0, s1, ta, tb, depth + 1
                top += 1
    return True


# -- the uniform grid of generator edges and vertices -------------------------------------


class _Grid:
    """Segments (generator edges, and vertices as zero-length segments) in a uniform
    grid: each listed in every cell its bounding box overlaps."""

    def __init__(self, lo, hi, n_cells):
        span = np.maximum(hi - lo, 1e-300)
        side = (np.prod(span) / max(1.0, n_cells)) ** (1 / 3)
        self.dims = np.clip(np.ceil(span / np.maximum(side, 1e-300)), 1, 128).astype(np.int64)
        self.lo = lo
        self.cell = span / self.dims

    def fill(self, a, b):
        """CSR lists (offsets, items) of the segments ab in each cell."""
        return bin_boxes(self.lo, self.cell, self.dims, np.minimum(a, b), np.maximum(a, b))


@njit(cache=True, nogil=True)
def _hull_axes(P, k, axes):
    """Fixed separating axes of the hull of k = 3 or 4 points P (k, 3): the normal of
    every triple and, in each triple's plane, the normals of its sides (the axes that
    matter when the hull is flat). Written as unit rows of ``axes`` (16, 3), degenerate
    ones left out; returns their number."""
    m = 0
    scale = 0.0
    for i in range(k):
        for j in range(i + 1, k):
            e = _sub(_row(P, j), _row(P, i))
            scale = max(scale, np.sqrt(_dot(e, e)))
    if scale == 0.0:
        return 0
    for i in range(k):
        for j in range(i + 1, k):
            for l in range(j + 1, k):
                pi, pj, pl = _row(P, i), _row(P, j), _row(P, l)
                n = _cross(_sub(pj, pi), _sub(pl, pi))
                size = np.sqrt(_dot(n, n))
                if size <= 1e-9 * scale * scale:
                    continue
                n = _div(n, size)
                _set_row(axes, m, n)
                m += 1
                for (p, q) in ((pi, pj), (pj, pl), (pi, pl)):
                    s = _cross(n, _sub(q, p))
                    ss = np.sqrt(_dot(s, s))
                    if ss > 1e-9 * scale:
                        _set_row(axes, m, _div(s, ss))
                        m += 1
    return m


@njit(cache=True, nogil=True)
def _meets_hull(A, B, axes, n_axes, hmin, hmax, tol):
    """Whether segment AB comes within ``tol`` of a hull (conservative: False only
    when an axis separates them by more than tol). ``axes[:n_axes]`` are
    :func:`_hull_axes`, ``hmin``, ``hmax`` the hull's extent along them.

    Only these fixed axes: the cross products of AB with the hull's edges, the
    other axes of an exact separation test, rejected 0.3 % of the edges the fixed
    axes let through (tetrahedra of the city of boxes) at more than half the cost
    of the test; the exact filters behind the queries drop those edges anyway."""
    for r in range(n_axes):
        axis = _row(axes, r)
        sa, sb = _dot(A, axis), _dot(B, axis)
        if min(sa, sb) > hmax[r] + tol or max(sa, sb) < hmin[r] - tol:
            return False
    return True


@njit(cache=True, nogil=True)
def _slab_extent(P, k, x_lo, x_hi):
    """Box of the part of the hull of P[:k] with x_lo <= x <= x_hi, in y and z:
    (y_lo, y_hi, z_lo, z_hi). Its vertices are points of P in the slab and the
    crossings of the segments between them with the slab's planes. Empty
    (y_lo > y_hi) when the hull misses the slab."""
    y_lo, z_lo = np.inf, np.inf
    y_hi, z_hi = -np.inf, -np.inf
    for q in range(k):
        if x_lo <= P[q, 0] <= x_hi:
            y_lo, y_hi = min(y_lo, P[q, 1]), max(y_hi, P[q, 1])
            z_lo, z_hi = min(z_lo, P[q, 2]), max(z_hi, P[q, 2])
        for r in range(q + 1, k):
            for plane in (x_lo, x_hi):
                if (P[q, 0] - plane) * (P[r, 0] - plane) < 0:
                    f = (plane - P[q, 0]) / (P[r, 0] - P[q, 0])
                    y, z = P[q, 1] + f * (P[r, 1] - P[q, 1]), P[q, 2] + f * (P[r, 2] - P[q, 2])
                    y_lo, y_hi = min(y_lo, y), max(y_hi, y)
                    z_lo, z_hi = min(z_lo, z), max(z_hi, z)
    return y_lo, y_hi, z_lo, z_hi


@njit(cache=True, nogil=True)
def _inflated_box(P, k, tol):
    """Bounding box of P[:k] grown by tol: (lo, hi) as tuples."""
    l0, l1, l2 = np.inf, np.inf, np.inf
    h0, h1, h2 = -np.inf, -np.inf, -np.inf
    for q in range(k):
        l0, l1, l2 = min(l0, P[q, 0]), min(l1, P[q, 1]), min(l2, P[q, 2])
        h0, h1, h2 = max(h0, P[q, 0]), max(h1, P[q, 1]), max(h2, P[q, 2])
    return (l0 - tol, l1 - tol, l2 - tol), (h0 + tol, h1 + tol, h2 + tol)


@njit(cache=True, nogil=True)
def _hull_setup(P, k, axes, hmin, hmax):
    """The separating axes of the hull of P[:k] (:func:`_hull_axes`) written to
    ``axes`` (16, 3), the hull's extent along them to ``hmin``, ``hmax`` (16,);
    returns their number."""
    n_axes = _hull_axes(P, k, axes)
    for r in range(n_axes):
        hmin[r], hmax[r] = np.inf, -np.inf
        axis = _row(axes, r)
        for q in range(k):
            s = _dot(_row(P, q), axis)
            hmin[r] = min(hmin[r], s)
            hmax[r] = max(hmax[r], s)
    return n_axes


@njit(cache=True, nogil=True)
def _query(P, k, tol, seg_a, seg_b, lo, cell, dims, offsets, items, stamp, stamp_id, out, axes, n_axes, hmin, hmax):
    """Indices of the segments meeting the inflated hull of P[:k]; writes them to
    ``out`` and returns their count (``stamp`` marks segments already seen).
    ``axes``, ``n_axes``, ``hmin``, ``hmax``: :func:`_hull_setup` of the hull.

    Only the cells near the hull are visited: per x-slab of cells, those within
    ``tol`` of the hull's part in the slab (widened by ``tol``). The indices come
    in the order of a scan of every cell of the hull's box (x, y, z, then index),
    so that the result does not depend on which cells were visited."""
    blo, bhi = _inflated_box(P, k, tol)
    c0 = (cell_of(blo[0], lo[0], cell[0], dims[0]), cell_of(blo[1], lo[1], cell[1], dims[1]), cell_of(blo[2], lo[2], cell[2], dims[2]))
    c1 = (cell_of(bhi[0], lo[0], cell[0], dims[0]), cell_of(bhi[1], lo[1], cell[1], dims[1]), cell_of(bhi[2], lo[2], cell[2], dims[2]))
    n_items = seg_a.shape[0]
    m = 0
    for x in range(c0[0], c1[0] + 1):
        # the slab of cell column x, unbounded at the grid's border (cell_of clamps)
        x_lo = lo[0] + x * cell[0] - tol if x > 0 else -np.inf
        x_hi = lo[0] + (x + 1) * cell[0] + tol if x < dims[0] - 1 else np.inf
        y_lo, y_hi, z_lo, z_hi = _slab_extent(P, k, x_lo, x_hi)
        if not y_lo <= y_hi:
            continue
        y0 = max(c0[1], cell_of(y_lo - tol, lo[1], cell[1], dims[1]))
        y1 = min(c1[1], cell_of(y_hi + tol, lo[1], cell[1], dims[1]))
        z0 = max(c0[2], cell_of(z_lo - tol, lo[2], cell[2], dims[2]))
        z1 = min(c1[2], cell_of(z_hi + tol, lo[2], cell[2], dims[2]))
        for y in range(y0, y1 + 1):
            for z in range(z0, z1 + 1):
                c = (x * dims[1] + y) * dims[2] + z
                for j in range(offsets[c], offsets[c + 1]):
                    s = items[j]
                    if stamp[s] == stamp_id:
                        continue
                    stamp[s] = stamp_id
                    A, B = _row(seg_a, s), _row(seg_b, s)
                    if (
                        min(A[0], B[0]) > bhi[0]
                        or max(A[0], B[0]) < blo[0]
                        or min(A[1], B[1]) > bhi[1]
                        or max(A[1], B[1]) < blo[1]
                        or min(A[2], B[2]) > bhi[2]
                        or max(A[2], B[2]) < blo[2]
                    ):
                        continue
                    if _meets_hull(A, B, axes, n_axes, hmin, hmax, tol):
                        # sort key: the first cell of the box scan listing s (cells
                        # list their segments by index)
                        first = 0
                        for d in range(3):
                            first = first * dims[d] + max(c0[d], cell_of(min(A[d], B[d]), lo[d], cell[d], dims[d]))
                        out[m] = first * n_items + s
                        m += 1
    out[:m].sort()
    for r in range(m):
        out[r] %= n_items
    return m


@njit(cache=True, nogil=True)
def _hull_vertices(edges, n_edges, ev, vx, P, k, tol, axes, n_axes, hmin, hmax, stamp, stamp_id, out):
    """The vertices within ``tol`` of the hull of P[:k] (the test of :func:`_query`)
    among the endpoints of ``edges[:n_edges]``, the edges :func:`_query` found:
    every vertex the test passes is among them when each vertex has an edge, as
    the test passes the vertex's edges too (they contain it). Writes positions in
    the vertex table to ``out``, returns their count; ``stamp`` marks vertices
    already seen."""
    blo, bhi = _inflated_box(P, k, tol)
    m = 0
    for r in range(n_edges):
        for end in range(2):
            v = ev[edges[r], end]
            if stamp[v] == stamp_id:
                continue
            stamp[v] = stamp_id
            x = _row(vx, v)
            if x[0] > bhi[0] or x[0] < blo[0] or x[1] > bhi[1] or x[1] < blo[1] or x[2] > bhi[2] or x[2] < blo[2]:
                continue
            if _meets_hull(x, x, axes, n_axes, hmin, hmax, tol):
                out[m] = v
                m += 1
    return m


@njit(cache=True, nogil=True)
def _scope_in_hull(scope_a, scope_b, axes, n_axes, hmin, hmax, tol):
    """Whether a scope generator (segments ``scope_a[i]``–``scope_b[i]``; a vertex as a
    segment of length 0) passes :func:`_meets_hull`, the test of :func:`_query` and
    :func:`_hull_vertices`: when none does, no generator the query finds is in scope."""
    for i in range(scope_a.shape[0]):
        if _meets_hull(_row(scope_a, i), _row(scope_b, i), axes, n_axes, hmin, hmax, tol):
            return True
    return False


@njit(cache=True, nogil=True)
def _edges_blocked(table, a0, a1, b0, b1):
    t = table[a0, b0]
    return t >= 0 and table[a0, b1] == t and table[a1, b0] == t and table[a1, b1] == t


@njit(cache=True)
def _edge_pairs_blocked(table, ev):
    """:func:`_edges_blocked` for every pair of edges (endpoints ``ev`` (n, 2) as
    positions in ``table``), packed 64 pairs to a word: bit b of row a tells whether
    edges a and b are blocked; (n, ⌈n/64⌉) uint64. Half a megabyte for 2000 edges,
    where the four look-ups in the vertex table per pair missed the cache."""
    n = ev.shape[0]
    bits = np.zeros((n, (n + 63) // 64), dtype=np.uint64)
    one = np.uint64(1)
    for a in range(n):
        for b in range(a + 1, n):
            if _edges_blocked(table, ev[a, 0], ev[a, 1], ev[b, 0], ev[b, 1]):
                bits[a, b >> 6] |= one << np.uint64(b & 63)
                bits[b, a >> 6] |= one << np.uint64(a & 63)
    return bits


@njit(cache=True, nogil=True)
def _blocked(bits, a, b):
    """Whether edges a and b are blocked (:func:`_edge_pairs_blocked`); never without
    the table (an empty one: the scoped scans, which have no table over all pairs)."""
    if bits.shape[0] == 0:
        return False
    return (bits[a, b >> 6] >> np.uint64(b & 63)) & np.uint64(1) != 0


@njit(cache=True, nogil=True)
def _vertex_edge_blocked(table, v, b0, b1):
    if table.shape[0] == 0:  # no table: nothing known blocked (:func:`_blocked`)
        return False
    t = table[v, b0]
    return t >= 0 and table[v, b1] == t


@njit(cache=True, nogil=True)
def _adjacent(ev, a, b):
    return ev[a, 0] == ev[b, 0] or ev[a, 0] == ev[b, 1] or ev[a, 1] == ev[b, 0] or ev[a, 1] == ev[b, 1]


@njit(cache=True, nogil=True)
def _push(buf, n, row):
    if n == buf.shape[0]:
        bigger = np.empty((2 * buf.shape[0] + 16, buf.shape[1]), dtype=buf.dtype)
        bigger[:n] = buf[:n]
        buf = bigger
    for k in range(buf.shape[1]):
        buf[n, k] = row[k]
    return buf




@njit(cache=True, nogil=True)
def _ratio(num, den, scale):
    """num / den, or nan when den is within rounding of zero (a pole: anything goes)."""
    if abs(den) <= PARALLEL_TOLERANCE * scale:
        return np.nan
    return num / den


@njit(cache=True, nogil=True)
def _within(x, margin):
    """x in [margin, 1 - margin] up to PARAM_SLACK, or nan (undecided)."""
    return np.isnan(x) or (margin - PARAM_SLACK <= x <= 1.0 - margin + PARAM_SLACK)


@njit(cache=True, nogil=True)
def _margin(eps, length):
    return END_MARGIN * eps / length if length > 0 else 0.0


@njit(cache=True, nogil=True)
def _through_point(p, a0, da, d0, dd):
    """The line through point p meeting the lines a0 + s da and d0 + t dd: (s, t).

    It lies in the plane through p and each line; it meets line a where a crosses
    the plane through p and line d (normal (d0 - p) × dd), and vice versa. nan
    where a line is parallel to the other's plane (no unique answer)."""
    n_d = _cross(_sub(d0, p), dd)
    n_a = _cross(_sub(a0, p), da)
    s = _ratio(_dot(_sub(p, a0), n_d), _dot(da, n_d), np.sqrt(_dot(da, da) * _dot(n_d, n_d)))
    t = _ratio(_dot(_sub(p, d0), n_a), _dot(dd, n_a), np.sqrt(_dot(dd, dd) * _dot(n_a, n_a)))
    return s, t


@njit(cache=True, nogil=True)
def _param_on(o, d, b0, db):
    """Parameter on line b0 + u db of its point closest to the line o + λ d, and λ
    there (nan, nan when parallel)."""
    w = _sub(b0, o)
    aa, bb, cc = _dot(d, d), _dot(d, db), _dot(db, db)
    dw, ew = _dot(d, w), _dot(db, w)
    den = aa * cc - bb * bb
    if den <= PARALLEL_TOLERANCE * aa * cc:
        return np.nan, np.nan
    u = (bb * dw - aa * ew) / den
    lam = (dw + bb * u) / aa
    return u, lam


@njit(cache=True, nogil=True)
def _between(A, D, b0, db, eps):
    """Whether the line AD meets segment b away from its ends, between A and D and
    away from them (the ε rules of validation, with END_MARGIN)."""
    AD = _sub(D, A)
    u, lam = _param_on(A, AD, b0, db)
    return _within(u, _margin(eps, np.sqrt(_dot(db, db)))) and _within(lam, _margin(eps, np.sqrt(_dot(AD, AD))))


@njit(cache=True, nogil=True)
def _side_coefficients(a0, da, d0, dd, b0, db):
    """f(s, t) = α + βs + γt + δst, the side product of line b with the line through
    a0 + s da and d0 + t dd (zero iff they meet). The line is (D - A, A × D), and
    side(L, L_b) = (D - A)·m_b + d_b·(A × D) is bilinear.

    Returns whether f vanishes identically (to rounding: b lies in the plane of
    a and d), and (α, β, γ, δ) normalised (zeros when f is exactly zero)."""
    mb = _cross(b0, db)
    alpha = _dot(_sub(d0, a0), mb) + _dot(db, _cross(a0, d0))
    beta = -_dot(da, mb) + _dot(db, _cross(da, d0))
    gamma = _dot(dd, mb) + _dot(db, _cross(a0, dd))
    delta = _dot(db, _cross(da, dd))
    size = max(max(abs(alpha), abs(beta)), max(abs(gamma), abs(delta)))
    # a bound on every term: what rounding is relative to
    na, nd, nb = np.sqrt(_dot(a0, a0)) + np.sqrt(_dot(da, da)), np.sqrt(_dot(d0, d0)) + np.sqrt(_dot(dd, dd)), np.sqrt(_dot(db, db))
    scale = (na + nd) * np.sqrt(_dot(mb, mb)) + nb * na * nd
    f = (0.0, 0.0, 0.0, 0.0)
    if size > 0:
        f = (alpha / size, beta / size, gamma / size, delta / size)
    return size <= IN_PLANE * scale, f


@njit(cache=True, nogil=True)
def _coplanar(a0, da, d0, dd):
    """Whether lines a and d lie in one plane (parallel, or meeting), to rounding."""
    n = _cross(da, dd)
    size = np.sqrt(_dot(n, n))
    scale = np.sqrt(_dot(da, da) * _dot(dd, dd))
    if size <= COPLANAR * scale:
        return True
    w = _sub(d0, a0)
    return abs(_dot(w, n)) <= COPLANAR * np.sqrt(_dot(w, w)) * scale


@njit(cache=True, nogil=True)
def _crosses_plane_at_end(a0, da, d0, dd, b0, db, eps):
    """For coplanar lines a and d: whether segment b crosses their plane steeply
    (sin ≥ 0.1) at a point within ε/2 of one of its ends, or outside it.

    Then no line of the plane meets b farther than ε from its ends (see
    :func:`_four_lines_meet`)."""
    w = _sub(d0, a0)
    n = _cross(da, w)
    n_far = _cross(da, _sub(_add(d0, dd), a0))
    if _dot(n, n) < _dot(n_far, n_far):
        n = n_far
    size = np.sqrt(_dot(n, n))
    length = np.sqrt(_dot(db, db))
    if size <= ANGLE_TOLERANCE * np.sqrt(_dot(da, da)) * np.sqrt(_dot(w, w) + _dot(dd, dd)) or length == 0:
        return False
    n = _div(n, size)
    h0, h1 = _dot(_sub(b0, a0), n), _dot(_sub(_add(b0, db), a0), n)
    if abs(h1 - h0) < 0.1 * length:
        return False
    u = h0 / (h0 - h1)
    return u * length < 0.5 * eps or (1 - u) * length < 0.5 * eps


@njit(cache=True, nogil=True)
def _arc_box(a0, da, d0, dd, b0, db, slack):
    """The box (s_lo, s_hi, t_lo, t_hi) in the (s, t) square of the lines through a
    point of segment b meeting lines a and d; empty (s_lo > s_hi) when it misses the
    square.

    Along b, s(u) and t(u) are linear-fractional (numerator and denominator of
    :func:`_through_point` are linear in u: the quadratic term is a triple product
    with a repeated vector), so monotone between poles: the box is spanned by
    u = 0 and u = 1 unless a denominator changes sign on [0, 1]."""
    b1 = _add(b0, db)
    s_lo, s_hi = _arc_range(_sub(b0, a0), _sub(b1, a0), da, _cross(_sub(d0, b0), dd), _cross(_sub(d0, b1), dd), slack)
    t_lo, t_hi = _arc_range(_sub(b0, d0), _sub(b1, d0), dd, _cross(_sub(a0, b0), da), _cross(_sub(a0, b1), da), slack)
    return s_lo, s_hi, t_lo, t_hi


@njit(cache=True, nogil=True)
def _arc_range(x0, x1, dx, n0, n1, slack):
    """One side of :func:`_arc_box`: the range of x·n / dx·n between the ends of b
    (x from the outer edge's origin to b's end, n the normal of the plane through
    that end and the other outer edge), clipped to [-slack, 1 + slack]."""
    m0, m1 = _dot(dx, n0), _dot(dx, n1)
    scale = np.sqrt(_dot(dx, dx)) * max(np.sqrt(_dot(n0, n0)), np.sqrt(_dot(n1, n1)))
    if m0 * m1 <= 0 or min(abs(m0), abs(m1)) <= 1e-9 * scale:
        lo, hi = -np.inf, np.inf  # through a pole: unbounded
    else:
        v0, v1 = _dot(x0, n0) / m0, _dot(x1, n1) / m1
        lo, hi = min(v0, v1), max(v0, v1)
    return max(lo, -slack), min(hi, 1.0 + slack)


@njit(cache=True, nogil=True)
def _four_lines_meet(a0, da, d0, dd, fb, fc, b0, db, c0, dc, eps):
    """The lines meeting segments a and d (at s, t), and segments b and c between
    them, with the ε margins of validation.

    Returns (n, s₀, t₀, s₁, t₁): the n ≤ 2 such lines found by the closed form, or
    n = -1 (undecided: any line may) wherever it is ill-conditioned (a family of
    lines, a double root, a pole).

    Solves f_b = f_c = 0 (bilinear): eliminating t gives
    Q(s) = (α_c + β_c s)(γ_b + δ_b s) - (α_b + β_b s)(γ_c + δ_c s) = 0; two
    well-separated roots are accurate to rounding."""
    nan = np.nan
    q2 = fc[1] * fb[3] - fb[1] * fc[3]
    q1 = fc[0] * fb[3] + fc[1] * fb[2] - fb[0] * fc[3] - fb[1] * fc[2]
    q0 = fc[0] * fb[2] - fb[0] * fc[2]
    big = max(abs(q2), max(abs(q1), abs(q0)))
    if big <= 1e-8:
        return -1, nan, nan, nan, nan  # dependent conditions: leave it to the exact solver
    root0 = root1 = 0.0
    n = 0
    if abs(q2) <= 1e-8 * big:
        if abs(q1) <= 1e-8 * big:
            return 0, nan, nan, nan, nan  # Q is a non-zero constant
        root0 = -q0 / q1
        n = 1
    else:
        disc = q1 * q1 - 4 * q2 * q0
        if abs(disc) <= 1e-6 * (q1 * q1 + 4 * abs(q2 * q0)):
            return -1, nan, nan, nan, nan  # a (near) double root: its position is ill-conditioned
        if disc < 0:
            return 0, nan, nan, nan, nan
        root = np.sqrt(disc)
        q = -0.5 * (q1 + (root if q1 >= 0 else -root))
        root0 = q / q2
        root1 = q0 / q
        n = 2
    ma, md = _margin(eps, np.sqrt(_dot(da, da))), _margin(eps, np.sqrt(_dot(dd, dd)))
    found = 0
    s_found, t_found = nan, nan
    for r in range(n):
        s = root0 if r == 0 else root1
        if not _within(s, ma):
            continue
        den_b, den_c = fb[2] + fb[3] * s, fc[2] + fc[3] * s
        if max(abs(den_b), abs(den_c)) <= 1e-6:
            # f_b and f_c hardly depend on t at this s, so Q vanishes here whatever
            # the lines (a root of the elimination, not of the system: e.g. where a
            # meets b while c and d are parallel). A line at s needs f = α + βs +
            # den·t = 0 for both, |α + βs| ≤ 1e-6 |t|: a clearly non-zero one leaves
            # no t in [-9, 10], also at the true root (within rounding of this one,
            # α..δ being normalised); otherwise any t may do
            if max(abs(fb[0] + fb[1] * s), abs(fc[0] + fc[1] * s)) > 1e-5:
                continue
            return -1, nan, nan, nan, nan
        if abs(den_b) >= abs(den_c):
            t = -(fb[0] + fb[1] * s) / den_b
        else:
            t = -(fc[0] + fc[1] * s) / den_c
        if not _within(t, md):
            continue
        A = _axpy(a0, s, da)
        D = _axpy(d0, t, dd)
        if _between(A, D, b0, db, eps) and _between(A, D, c0, dc, eps):
            if found == 0:
                s_found, t_found = s, t
            found += 1
    if found == 2:
        return 2, s_found, t_found, s, t
    return found, s_found, t_found, nan, nan


@njit(cache=True, nogil=True)
def _no_vee_line(p, lines, e1, e2):
    """Whether :func:`viscx.geometry.lines.line_through_point_and_two_lines` finds no
    line through point p meeting the Plücker lines ``lines[e1]`` and ``lines[e2]`` (6,) because the normals of the
    planes through p and each line, m - p × d, have a cross product of exactly zero
    (its operations in its order, so the same floats): e.g. a vertex and two edges of
    the floor. Tiny non-zero products are left to it."""
    n1 = _sub((lines[e1, 3], lines[e1, 4], lines[e1, 5]), _cross(p, (lines[e1, 0], lines[e1, 1], lines[e1, 2])))
    n2 = _sub((lines[e2, 3], lines[e2, 4], lines[e2, 5]), _cross(p, (lines[e2, 0], lines[e2, 1], lines[e2, 2])))
    d = _cross(n1, n2)
    return d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0


@njit(cache=True, nogil=True)
def _on_arc(x, start, length):
    """Whether angle x lies on the arc [start, start + length] of the circle of lines (angles mod π)."""
    return length >= np.pi or (x - start) % np.pi <= length


@njit(cache=True, nogil=True)
def _sight_arc(b0, b1, e1, e2, p, q, eps):
    """The arc (start, length) of angles mod π, in edge b's frame (e1, e2 ⊥ b), that the
    direction of a line meeting b and segment pq within ε (validation's (N1)) may take
    once projected along b (module docstring, "Inner edges are passed"); length ≥ π:
    any. Points of pq project to p', q' in the plane ⊥ b with b's line at the origin.
    A line through B' on b passing within ε of P' on pq has its projected direction
    within asin(2ε / |P'⊥|) of P'⊥'s, |P'⊥| ≥ ρ, the distance of segment p'q' from the
    origin. The inflation adds ``PASS_ANGLE`` and 1e-7 / |u⊥| for a unit direction u
    (|u⊥| ≥ (ρ - 2ε) / (the farthest two points of pq and b + 2ε)): the projected
    direction is then at least 1e-7 off each face's plane and off b itself, far above
    the grazing tolerances of the tangency test."""
    px, py = _dot(_sub(p, b0), e1), _dot(_sub(p, b0), e2)
    qx, qy = _dot(_sub(q, b0), e1), _dot(_sub(q, b0), e2)
    dx, dy = qx - px, qy - py
    dd = dx * dx + dy * dy
    t = 0.0 if dd == 0 else min(1.0, max(0.0, -(px * dx + py * dy) / dd))
    rho = np.hypot(px + t * dx, py + t * dy)
    if not rho > 8 * eps:
        return 0.0, np.pi
    far = 0.0
    for x in (p, q):
        for y in (b0, b1):
            w = _sub(x, y)
            far = max(far, np.sqrt(_dot(w, w)))
    grow = 1.1 * 2 * eps / rho + PASS_ANGLE + 1e-7 * (far + 2 * eps) / (rho - 2 * eps)
    ext = np.arctan2(px * qy - py * qx, px * qx + py * qy)
    start = np.arctan2(py, px) + min(ext, 0.0)
    return (start - grow) % np.pi, abs(ext) + 2 * grow


@njit(cache=True, nogil=True)
def _passable(b, ea, eb, pass_frame, pass_arc, p0, p1, q0, q1, eps):
    """Whether a line meeting segments p0p1 and q0q1 and edge b (b between them) may pass
    b (validation's (N2)): its direction's arc from each segment (:func:`_sight_arc`) and
    b's arc of passing directions (``pass_arc``, inflated) meet. Three arcs of a circle
    meet iff the start of one of them lies on the other two."""
    if pass_arc[b, 1] >= np.pi:
        return True
    b0, b1 = _row(ea, b), _row(eb, b)
    e1 = (pass_frame[b, 0, 0], pass_frame[b, 0, 1], pass_frame[b, 0, 2])
    e2 = (pass_frame[b, 1, 0], pass_frame[b, 1, 1], pass_frame[b, 1, 2])
    s1, l1 = _sight_arc(b0, b1, e1, e2, p0, p1, eps)
    s2, l2 = _sight_arc(b0, b1, e1, e2, q0, q1, eps)
    s3, l3 = pass_arc[b, 0], pass_arc[b, 1]
    if l1 < np.pi and _on_arc(s1, s2, l2) and _on_arc(s1, s3, l3):
        return True
    if l2 < np.pi and _on_arc(s2, s1, l1) and _on_arc(s2, s3, l3):
        return True
    return _on_arc(s3, s1, l1) and _on_arc(s3, s2, l2)


@njit(cache=True, nogil=True)
def _scan_edge_pairs(
    first, ev, ea, eb, ed, lines, vx, table, blocked, sov, lo, cell, dims, e_off, e_items, v_off, v_items, tol, eps,
    scope_e, scope_v, scope_a, scope_b, partner_off, partners, s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items,
    pass_frame, pass_arc
):
    """Outer edge pairs (a, d), a in ``first``, d > a (or, with ``partner_off`` non-empty,
    d in ``partners[partner_off[a]:partner_off[a + 1]]``): the vertices and edge pairs in
    their inflated hull with every pair of generators unblocked and a line through
    all of them (exact filters, with slack).

    ``ev`` holds the edges' endpoints as positions in the vertex table, ``ed`` their
    directions eb - ea, ``lines`` their Plücker lines (n_edges, 6); ``e_off``,
    ``e_items`` the grid of the edges, ``v_off``, ``v_items`` that of the vertices
    without an edge (none in a scene of polygons). Returns VEE rows (v, a, d) and
    E4 rows (a, b, c, d) unsorted, by position."""
    n_e = ev.shape[0]
    n_v = vx.shape[0]
    e_stamp = np.full(n_e, -1, dtype=np.int64)
    v_stamp = np.full(n_v, -1, dtype=np.int64)
    s_stamp = np.full(max(s_planes_off.shape[0] - 1, 1), -1, dtype=np.int64)
    s_counter = np.zeros(1, dtype=np.int64)
    e_out = np.empty(n_e, dtype=np.int64)
    v_out = np.empty(n_v, dtype=np.int64)
    inner = np.empty(n_e, dtype=np.int64)
    coef = np.empty((n_e, 4))
    box = np.empty((n_e, 4))
    with_a = np.empty(n_e, dtype=np.bool_)
    with_d = np.empty(n_e, dtype=np.bool_)
    vee = np.empty((1024, 3), dtype=np.int64)
    quad = np.empty((1024, 4), dtype=np.int64)
    n_vee = 0
    n_quad = 0
    P = np.empty((4, 3))
    axes = np.empty((16, 3))
    hmin = np.empty(16)
    hmax = np.empty(16)
    row3 = np.empty(3, dtype=np.int64)
    row4 = np.empty(4, dtype=np.int64)
    # the outer generator points of a line, for Lemma 2 (:func:`_crosses_solid`)
    ends = np.empty((2, 3))
    ends_owner = np.empty(2, dtype=np.int64)
    ends_t = np.array([0.0, 1.0])
    query = 0
    for a in first:
        a0, a1 = ev[a, 0], ev[a, 1]
        pa, qa, da = _row(ea, a), _row(eb, a), _row(ed, a)
        len_a = np.sqrt(_dot(da, da))
        listed = partner_off.shape[0] > 0
        n_d = partner_off[a + 1] - partner_off[a] if listed else n_e - a - 1
        for k in range(n_d):
            d = partners[partner_off[a] + k] if listed else a + 1 + k
            if _adjacent(ev, a, d):
                continue
            d0, d1 = ev[d, 0], ev[d, 1]
            if _blocked(blocked, a, d):
                continue
            pd, qd, dd = _row(ea, d), _row(eb, d), _row(ed, d)
            if _pair_hidden(pa, qa, pd, qd, True, sov[a0], sov[d0], s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items, s_stamp, s_counter):
                continue
            len_d = np.sqrt(_dot(dd, dd))
            ends_owner[0], ends_owner[1] = sov[a0], sov[d0]
            slack = POINT_SLACK * eps + PARAM_SLACK * max(len_a, len_d)
            _set_row(P, 0, _row(vx, a0))
            _set_row(P, 1, _row(vx, a1))
            _set_row(P, 2, _row(vx, d0))
            _set_row(P, 3, _row(vx, d1))
            query += 1
            n_axes = _hull_setup(P, 4, axes, hmin, hmax)
            ad_in = scope_e[a] or scope_e[d]
            if not ad_in and not _scope_in_hull(scope_a, scope_b, axes, n_axes, hmin, hmax, tol):
                continue
            ne = _query(P, 4, tol, ea, eb, lo, cell, dims, e_off, e_items, e_stamp, query, e_out, axes, n_axes, hmin, hmax)
            nv = _hull_vertices(e_out, ne, ev, vx, P, 4, tol, axes, n_axes, hmin, hmax, v_stamp, query, v_out)
            if v_items.shape[0]:  # vertices without a generator edge
                nv += _query(P, 4, tol, vx, vx, lo, cell, dims, v_off, v_items, v_stamp, query, v_out[nv:], axes, n_axes, hmin, hmax)
            for r in range(nv):
                v = v_out[r]
                if v == a0 or v == a1 or v == d0 or v == d1 or not (ad_in or scope_v[v]):
                    continue
                if _vertex_edge_blocked(table, v, a0, a1) or _vertex_edge_blocked(table, v, d0, d1):
                    continue
                # the line through v meeting lines a and d: inside both segments, v between
                pv = _row(vx, v)
                s, t = _through_point(pv, pa, da, pd, dd)
                if not (_within(s, _margin(eps, len_a)) and _within(t, _margin(eps, len_d))):
                    continue
                if not (np.isnan(s) or np.isnan(t)):
                    A = _axpy(pa, s, da)
                    D = _axpy(pd, t, dd)
                    AD = _sub(D, A)
                    dad = _dot(AD, AD)
                    if dad > 0 and not _within(_dot(_sub(pv, A), AD) / dad, _margin(eps, np.sqrt(dad))):
                        continue
                    # Lemma 2 on the line: a, d foreign to a solid whose inner copy [A, D] crosses
                    _set_row(ends, 0, A)
                    _set_row(ends, 1, D)
                    s_counter[0] += 1
                    if _crosses_solid(ends, ends_owner, ends_t, s_counter[0], s_stamp, slack, s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items):
                        continue
                if _no_vee_line(pv, lines, a, d):
                    continue
                row3[0], row3[1], row3[2] = v, a, d
                vee = _push(vee, n_vee, row3)
                n_vee += 1
            coplanar = _coplanar(pa, da, pd, dd)
            # inner edge candidates and their arcs in the (s, t) square of lines meeting a and d
            m = 0
            for r in range(ne):
                b = e_out[r]
                if b == a or b == d or _adjacent(ev, a, b) or _adjacent(ev, b, d):
                    continue
                if _blocked(blocked, a, b) or _blocked(blocked, b, d):
                    continue
                pb, db = _row(ea, b), _row(ed, b)
                arc = _arc_box(pa, da, pd, dd, pb, db, 1e-6)
                if arc[0] > arc[1] or arc[2] > arc[3]:
                    continue
                # b in the plane of a and d: three coplanar lines, so with any fourth
                # the solutions form a family or there are none (module docstring)
                in_plane, f = _side_coefficients(pa, da, pd, dd, pb, db)
                if in_plane:
                    continue
                # a and d coplanar: every line meeting both lies in their plane and
                # meets b where b crosses it; near b's end that is no node
                if coplanar and _crosses_plane_at_end(pa, da, pd, dd, pb, db, eps):
                    continue
                # an inner edge must be passed: by a direction the outer edges allow
                if not _passable(b, ea, eb, pass_frame, pass_arc, pa, qa, pd, qd, eps):
                    continue
                inner[m] = b
                box[m, 0], box[m, 1], box[m, 2], box[m, 3] = arc
                coef[m, 0], coef[m, 1], coef[m, 2], coef[m, 3] = f
                with_a[m] = _coplanar(pa, da, pb, db)
                with_d[m] = _coplanar(pd, dd, pb, db)
                m += 1
            for i in range(m):
                b = inner[i]
                pb, db, fb = _row(ea, b), _row(ed, b), _row4(coef, i)
                for j in range(i + 1, m):
                    if box[j, 0] > box[i, 1] or box[i, 0] > box[j, 1] or box[j, 2] > box[i, 3] or box[i, 2] > box[j, 3]:
                        continue
                    c = inner[j]
                    if _adjacent(ev, b, c) or not (ad_in or scope_e[b] or scope_e[c]):
                        continue
                    if _blocked(blocked, b, c):
                        continue
                    pc, dc = _row(ea, c), _row(ed, c)
                    # three pairwise coplanar lines (in one plane, or through one
                    # point): a family of solutions or none (module docstring)
                    if ((with_a[i] and with_a[j]) or (with_d[i] and with_d[j])) and _coplanar(pb, db, pc, dc):
                        continue
                    n_lines, s0, t0, s1, t1 = _four_lines_meet(pa, da, pd, dd, fb, _row4(coef, j), pb, db, pc, dc, eps)
                    if n_lines == 0:
                        continue
                    if n_lines > 0:
                        # Lemma 2 on each line: a, d foreign to a solid whose inner copy
                        # [A, D] crosses (with the slack of the closed form)
                        all_blocked = True
                        for r in range(n_lines):
                            _set_row(ends, 0, _axpy(pa, s0 if r == 0 else s1, da))
                            _set_row(ends, 1, _axpy(pd, t0 if r == 0 else t1, dd))
                            s_counter[0] += 1
                            if not _crosses_solid(ends, ends_owner, ends_t, s_counter[0], s_stamp, slack, s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items):
                                all_blocked = False
                                break
                        if all_blocked:
                            continue
                    row4[0], row4[1], row4[2], row4[3] = a, b, c, d
                    quad = _push(quad, n_quad, row4)
                    n_quad += 1
    return vee[:n_vee], quad[:n_quad]


@njit(cache=True, nogil=True)
def _scan_vertex_edges(
    first, ev, ea, eb, ed, lines, vx, table, blocked, sov, lo, cell, dims, e_off, e_items, tol, eps,
    scope_e, scope_v, scope_a, scope_b, partner_off, partners, s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items,
    pass_frame, pass_arc
):
    """Vertex v (positions in ``first``) at an end, the far edge e (every edge, or those
    listed for v as in :func:`_scan_edge_pairs`): the edges in the
    inflated triangle conv(v ∪ e) with every pair of generators unblocked and a line
    through v, them and e (exact filter, with slack).
    Returns rows (v, e1, e2) by position, e1 the inner edge. Scope as :func:`_scan_edge_pairs`."""
    n_e = ev.shape[0]
    e_stamp = np.full(n_e, -1, dtype=np.int64)
    e_out = np.empty(n_e, dtype=np.int64)
    s_stamp = np.full(max(s_planes_off.shape[0] - 1, 1), -1, dtype=np.int64)
    s_counter = np.zeros(1, dtype=np.int64)
    vee = np.empty((1024, 3), dtype=np.int64)
    n_vee = 0
    P = np.empty((4, 3))
    axes = np.empty((16, 3))
    hmin = np.empty(16)
    hmax = np.empty(16)
    row3 = np.empty(3, dtype=np.int64)
    # the outer generator points of a line, for Lemma 2 (:func:`_crosses_solid`)
    ends = np.empty((2, 3))
    ends_owner = np.empty(2, dtype=np.int64)
    ends_t = np.array([0.0, 1.0])
    query = 0
    for v in first:
        pv = _row(vx, v)
        listed = partner_off.shape[0] > 0
        n_f = partner_off[v + 1] - partner_off[v] if listed else n_e
        for k in range(n_f):
            e = partners[partner_off[v] + k] if listed else k
            e0, e1 = ev[e, 0], ev[e, 1]
            if e0 == v or e1 == v or _vertex_edge_blocked(table, v, e0, e1):
                continue
            pe, qe, de = _row(ea, e), _row(eb, e), _row(ed, e)
            if _pair_hidden(pv, pv, pe, qe, False, sov[v], sov[e0], s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items, s_stamp, s_counter):
                continue
            ends_owner[0], ends_owner[1] = sov[v], sov[e0]
            slack = POINT_SLACK * eps + PARAM_SLACK * np.sqrt(_dot(de, de))
            _set_row(P, 0, pv)
            _set_row(P, 1, _row(vx, e0))
            _set_row(P, 2, _row(vx, e1))
            query += 1
            n_axes = _hull_setup(P, 3, axes, hmin, hmax)
            ve_in = scope_v[v] or scope_e[e]
            if not ve_in and not _scope_in_hull(scope_a, scope_b, axes, n_axes, hmin, hmax, tol):
                continue
            ne = _query(P, 3, tol, ea, eb, lo, cell, dims, e_off, e_items, e_stamp, query, e_out, axes, n_axes, hmin, hmax)
            for r in range(ne):
                b = e_out[r]
                b0, b1 = ev[b, 0], ev[b, 1]
                if b == e or b0 == v or b1 == v or _adjacent(ev, b, e) or not (ve_in or scope_e[b]):
                    continue
                if _vertex_edge_blocked(table, v, b0, b1) or _blocked(blocked, b, e):
                    continue
                if not _passable(b, ea, eb, pass_frame, pass_arc, pv, pv, pe, qe, eps):
                    continue
                # lines through v meeting e at e(t) meet line b where v, e(t), b are
                # coplanar: (e(t) - v) · n_b = 0 with n_b the normal of plane (v, b)
                pb, db = _row(ea, b), _row(ed, b)
                n_b = _cross(_sub(pb, pv), db)
                t = _ratio(-_dot(_sub(pe, pv), n_b), _dot(de, n_b), np.sqrt(_dot(de, de) * _dot(n_b, n_b)))
                if not _within(t, _margin(eps, np.sqrt(_dot(de, de)))):
                    continue
                if not np.isnan(t):
                    E = _axpy(pe, t, de)
                    if not _between(pv, E, pb, db, eps):
                        continue
                    # Lemma 2 on the line: v, e foreign to a solid whose inner copy [v, E] crosses
                    _set_row(ends, 0, pv)
                    _set_row(ends, 1, E)
                    s_counter[0] += 1
                    if _crosses_solid(ends, ends_owner, ends_t, s_counter[0], s_stamp, slack, s_planes_off, s_planes, s_lo, s_cell, s_dims, s_off, s_items):
                        continue
                if _no_vee_line(pv, lines, b, e):
                    continue
                row3[0], row3[1], row3[2] = v, b, e
                vee = _push(vee, n_vee, row3)
                n_vee += 1
    return vee[:n_vee]


def _parallel(kernel, items, args, chunk, progress_bar, workers):
    """``kernel(items_chunk, *args)`` over chunks of ``items`` on threads (the kernels
    release the GIL), in order."""
    chunks = [items[i : i + chunk] for i in range(0, len(items), chunk)]
    return map_chunks(lambda part: kernel(part, *args), chunks, workers, progress=lambda part: progress_bar.update(len(part)))


def _met_loosely(scene, origins, directions, vertex_ids, edge_ids, solids):
    """(N1) with doubled tolerances: within 2ε of every generator, edge points at
    least ε/2 inside their edges, consecutive points more than ε/2 apart; and no
    two generators foreign to a blocking solid whose generator points are joined
    across the solid's inner copy (Lemma 2 on this line).

    Parameters
    ----------
    origins, directions : (m, 3) float
    vertex_ids : (m, p) int
        Vertex generators (p may be 0).
    edge_ids : (m, q) int
    solids : tuple
        Blocking solid of each scene vertex (n_vertices,) int, then
        :meth:`_SolidGrid.args`.

    Returns
    -------
    (m,) bool
    """
    return _loose_lines(
        np.ascontiguousarray(origins, dtype=np.float64),
        np.ascontiguousarray(directions, dtype=np.float64),
        np.ascontiguousarray(vertex_ids, dtype=np.int64),
        np.ascontiguousarray(edge_ids, dtype=np.int64),
        scene.vertices,
        scene.half_edges.edge_vertices,
        scene.epsilon,
        *solids,
    )


@njit(cache=True, nogil=True)
def _loose_lines(origins, directions, vertex_ids, edge_ids, vertices, ev, eps, solid_of_vertex, plane_offsets, planes, lo, cell, dims, offsets, items):
    """:func:`_met_loosely` row by row: validation's formulas (canonical unit direction,
    closest points of the edges' lines) with its tolerances doubled; the solids
    only for lines that pass."""
    m, n_v, n_e = origins.shape[0], vertex_ids.shape[1], edge_ids.shape[1]
    k = n_v + n_e
    ok = np.zeros(m, dtype=np.bool_)
    points = np.empty((k, 3))
    owner = np.empty(k, dtype=np.int64)
    t = np.empty(k)
    stamp = np.full(max(plane_offsets.shape[0] - 1, 1), -1, dtype=np.int64)
    has_solids = planes.shape[0] > 0
    for i in range(m):
        o, raw = _row(origins, i), _row(directions, i)
        d = _div(raw, np.sqrt(_dot(raw, raw)))
        if d[0] + 1e-3 * d[1] + 1e-6 * d[2] < 0:
            d = (-d[0], -d[1], -d[2])
        good = True
        for j in range(n_v):
            x = _row(vertices, vertex_ids[i, j])
            w = _sub(x, o)
            c = _cross(w, d)
            if not np.sqrt(_dot(c, c)) <= 2 * eps:
                good = False
                break
            points[j, 0], points[j, 1], points[j, 2] = x[0], x[1], x[2]
            owner[j] = solid_of_vertex[vertex_ids[i, j]]
            t[j] = _dot(w, d)
        for j in range(n_e if good else 0):
            a, b = _row(vertices, ev[edge_ids[i, j], 0]), _row(vertices, ev[edge_ids[i, j], 1])
            e, w = _sub(b, a), _sub(a, o)
            aa, bb, cc, dw, ew = _dot(d, d), _dot(d, e), _dot(e, e), _dot(d, w), _dot(e, w)
            den = aa * cc - bb * bb
            if not den > 1e-14 * aa * cc:
                good = False  # parallel
                break
            x = (bb * dw - aa * ew) / den
            lam = (dw + bb * x) / aa
            gap = _sub(_axpy(w, x, e), (lam * d[0], lam * d[1], lam * d[2]))
            length = np.sqrt(cc)
            if not (np.sqrt(_dot(gap, gap)) <= 2 * eps and x * length > 0.5 * eps and (1 - x) * length > 0.5 * eps):
                good = False
                break
            q = _axpy(a, x, e)
            points[n_v + j, 0], points[n_v + j, 1], points[n_v + j, 2] = q[0], q[1], q[2]
            owner[n_v + j] = solid_of_vertex[ev[edge_ids[i, j], 0]]
            t[n_v + j] = _dot(_sub(q, o), d)
        if not good:
            continue
        ts = np.sort(t)
        for j in range(k - 1):
            if not ts[j + 1] - ts[j] > 0.5 * eps:
                good = False
        if good and has_solids:
            good = not _crosses_solid(points, owner, t, i, stamp, 0.0, plane_offsets, planes, lo, cell, dims, offsets, items)
        ok[i] = good
    return ok


@njit(cache=True, nogil=True)
def _crosses_solid(points, owner, t, stamp_id, stamp, margin, plane_offsets, planes, lo, cell, dims, offsets, items):
    """Whether, for some blocking solid, the generator points of a line that are
    foreign to it and outermost along the line are joined across its inner copy.
    Lemma 2 on one line: then the line is no node. Conservative (the solids are
    found along the line's span by steps shorter than a cell).

    Parameters
    ----------
    points : (k, 3) float
        Generator points of the line.
    owner : (k,) int
        Blocking solid of each generator (-1 for none).
    t : (k,) float
        Their parameters along the line.
    stamp_id, stamp
        ``stamp`` marks solids already tried for this line (``stamp_id``).
    margin : float
        The solids' planes are moved inwards by this much (0: the inner copies
        themselves).
    plane_offsets, planes, lo, cell, dims, offsets, items
        :meth:`_SolidGrid.args`.
    """
    k = owner.shape[0]
    small = min(cell[0], min(cell[1], cell[2]))
    first, last = 0, 0
    for j in range(1, k):
        if t[j] < t[first]:
            first = j
        if t[j] > t[last]:
            last = j
    P = _row(points, first)
    span = _sub(_row(points, last), P)
    steps = int(np.sqrt(_dot(span, span)) / small) + 1
    for step in range(steps + 1):
        X = _axpy(P, step / steps, span)
        c = (cell_of(X[0], lo[0], cell[0], dims[0]) * dims[1] + cell_of(X[1], lo[1], cell[1], dims[1])) * dims[2] + cell_of(X[2], lo[2], cell[2], dims[2])
        for j in range(offsets[c], offsets[c + 1]):
            solid = items[j]
            if stamp[solid] == stamp_id:
                continue
            stamp[solid] = stamp_id
            x, y = -1, -1
            for g in range(k):
                if owner[g] != solid:
                    if x < 0 or t[g] < t[x]:
                        x = g
                    if y < 0 or t[g] > t[y]:
                        y = g
            if x >= 0 and x != y and _segment_meets_solid(_row(points, x), _row(points, y), solid, plane_offsets, planes, margin):
                return True
    return False


def fast_candidates(scene, progress=None, workers=None, stats=None, scope=None):
    """Candidate lines that include every node's, in the reference's form.

    Parameters
    ----------
    scene : Scene
    progress : callable, optional
        ``progress(desc, total)`` returns a tqdm-like bar (``update``, ``close``);
        default: no bars.
    workers : int, optional
        Threads for the hull scans (default: the CPU count).
    stats : dict, optional
        Filled with the counts of each stage (pairs, tuples, candidates per kind).
    scope : viscx.skeleton.scope.Scope, optional
        Only the tuples with a generator in scope (:meth:`~viscx.skeleton.scope.Scope.nodes`),
        dropped before their lines are solved: the others' candidates are unchanged.

    Returns
    -------
    kind : (m,) int8
    generators : (m, 4) int
    origins, directions : (m, 3) float
        As :func:`viscx.skeleton.reference.reference_candidates`.
    """
    if progress is None:
        progress = lambda desc, total: bar(total, desc, quiet=True)  # noqa: E731
    workers = workers or os.cpu_count() or 1
    eps = scene.epsilon
    gv = scene.generator_vertices
    ge = scene.generator_edges
    ev_all = scene.half_edges.edge_vertices
    stats = {} if stats is None else stats
    out = []
    if len(gv) < 2:
        return _pack(out)
    clock = time.perf_counter()
    pos = np.full(scene.n_vertices, -1, dtype=np.int64)
    pos[gv] = np.arange(len(gv))
    solids = blocking_solids(scene)
    if scope is None:
        table, sov = blocked_table(scene, gv, solids)
    else:  # light-centred: no table over all pairs of generators (g² of them)
        table, sov = np.full((0, 0), -1, np.int32), solids[0][gv]
    solid_grid = _SolidGrid(*solids[1:]).args()
    line_solids = (solids[0],) + solid_grid
    stats["seconds solids"] = time.perf_counter() - clock
    vx = np.ascontiguousarray(scene.vertices[gv])
    ev = pos[ev_all[ge]]  # generator edges by vertex position

    # VV: unblocked pairs not joined by an edge, free as validation will test them
    clock = time.perf_counter()
    pb = progress("VV", len(gv))
    if scope is None:
        i, j = np.triu_indices(len(gv), 1)
        keep = table[i, j] < 0
        joined = np.zeros((len(gv), len(gv)), dtype=bool)
        joined[ev[:, 0], ev[:, 1]] = joined[ev[:, 1], ev[:, 0]] = True
        keep &= ~joined[i, j]
    else:  # the pairs with a scope vertex, i < j, not joined by an edge
        s = np.flatnonzero(scope.node_vertices[gv])
        i, j = np.repeat(s, len(gv)), np.tile(np.arange(len(gv)), len(s))
        i, j = np.minimum(i, j), np.maximum(i, j)
        i, j = unique_rows(np.stack([i, j], axis=1)[i < j])[0].T
        keep = ~np.isin(i * len(gv) + j, np.sort(ev, axis=1) @ np.array([len(gv), 1]))
    i, j = i[keep], j[keep]
    u, v = gv[i], gv[j]
    origin, direction = scene.vertices[u], scene.vertices[v] - scene.vertices[u]
    d = canonical_directions(direction)
    forward = np.einsum("ij,ij->i", scene.vertices[v] - origin, d) >= 0
    first = np.where(forward[:, None], scene.vertices[u], scene.vertices[v])
    last = np.where(forward[:, None], scene.vertices[v], scene.vertices[u])
    free = free_pieces(scene, first, last)
    pb.update(len(gv))
    pb.close()
    stats["VV pairs"] = int(len(gv) * (len(gv) - 1) // 2)
    stats["VV unblocked"] = int(len(u))
    u, v = u[free], v[free]
    gens = np.stack([u, v, np.full_like(u, -1), np.full_like(u, -1)], axis=1)
    out.append((np.full(len(u), VV), gens, scene.vertices[u], scene.vertices[v] - scene.vertices[u]))
    stats["VV candidates"] = int(len(u))
    stats["seconds VV"] = time.perf_counter() - clock
    if len(ge) < 2:
        return _pack(out)

    lo = vx.min(axis=0) - HULL_TOL * eps
    hi = vx.max(axis=0) + HULL_TOL * eps
    ea, eb = np.ascontiguousarray(vx[ev[:, 0]]), np.ascontiguousarray(vx[ev[:, 1]])
    ed = eb - ea
    blocked = _edge_pairs_blocked(table, ev) if scope is None else np.zeros((0, 1), np.uint64)
    # Plücker lines of the generator edges, once (the same floats as per tuple)
    lines = edge_lines(scene, ge)
    line_of = np.zeros((len(ev_all), 6))
    line_of[ge] = lines
    grid = _Grid(lo, hi, len(ge) / 2)
    e_off, e_items = grid.fill(ea, eb)
    # the E4 scan finds the vertices in a hull through their edges; those without
    # one (free points made generators) have a grid of their own
    lone = np.setdiff1d(np.arange(len(gv)), ev.ravel())
    v_off, v_items = grid.fill(vx[lone], vx[lone])
    v_items = lone[v_items]
    tol = HULL_TOL * eps + 1e-12 * scene.diagonal
    scoping = _scope_arrays(scope, gv, ge, ev, vx)
    passing = passing_arcs(scene, ge, ed)
    # the outer pairs the scans visit: all, or (scoped) those whose joint box meets a
    # scope generator's (light-centred: :func:`viscx.skeleton.scope.pairs_near`)
    if scope is None:
        ve_first, ve_pairs = np.arange(len(gv)), (np.zeros(0, np.int64), np.zeros(0, np.int64))
        ee_first, ee_pairs = np.arange(len(ge)), ve_pairs
    else:
        from viscx.skeleton.scope import pairs_near

        pad = 4 * tol + 4 * eps
        s_lo, s_hi = np.minimum(scoping[2], scoping[3]) - pad, np.maximum(scoping[2], scoping[3]) + pad
        e_lo, e_hi = np.minimum(ea, eb), np.maximum(ea, eb)
        ve_first, ve_pairs = pairs_near(s_lo, s_hi, vx, vx, e_lo, e_hi)
        ee_first, ee_pairs = pairs_near(s_lo, s_hi, e_lo, e_hi, e_lo, e_hi, same=True)
        stats["VEE outer pairs"], stats["E4 outer pairs"] = len(ve_pairs[1]), len(ee_pairs[1])

    # VEE with the vertex at an end: (v, e) pairs and the edges in their triangle
    clock = time.perf_counter()
    pb = progress("VEE", len(ve_first))
    parts = _parallel(
        _scan_vertex_edges,
        ve_first,
        (ev, ea, eb, ed, lines, vx, table, blocked, sov, grid.lo, grid.cell, grid.dims, e_off, e_items, tol, eps)
        + scoping + ve_pairs + solid_grid + passing,
        max(1, min(64, len(ve_first) // (8 * workers) + 1)),
        pb,
        workers,
    )
    pb.close()
    vee_end = np.concatenate(parts) if parts else np.zeros((0, 3), np.int64)
    stats["seconds VEE scan"] = time.perf_counter() - clock
    clock = time.perf_counter()

    # E4 and VEE with the vertex inside: outer edge pairs (a, d) and what their tetrahedron holds
    pb = progress("E4", len(ee_first))
    parts = _parallel(
        _scan_edge_pairs,
        ee_first,
        (ev, ea, eb, ed, lines, vx, table, blocked, sov, grid.lo, grid.cell, grid.dims, e_off, e_items, v_off, v_items, tol, eps)
        + scoping + ee_pairs + solid_grid + passing,
        max(1, min(64, len(ee_first) // (8 * workers) + 1)),
        pb,
        workers,
    )
    pb.close()
    vee_in = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, 3), np.int64)
    quads = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 4), np.int64)
    stats["seconds E4 scan"] = time.perf_counter() - clock
    clock = time.perf_counter()

    # VEE: canonical (v, e1 < e2), ids of the scene, deduplicated
    vee = np.concatenate([vee_end, vee_in])
    stats["VEE tuples"] = int(len(vee))
    v_id = gv[vee[:, 0]]
    e_lo, e_hi = ge[np.minimum(vee[:, 1], vee[:, 2])], ge[np.maximum(vee[:, 1], vee[:, 2])]
    vee = unique_rows(np.stack([v_id, e_lo, e_hi], axis=1))[0]
    if scope is not None:
        vee = vee[scope.nodes(np.full(len(vee), VEE), np.c_[vee, np.full(len(vee), -1)])]
    out.append(_lines_in_chunks(_vee_lines, vee, (scene, line_of, line_solids), workers))
    stats["VEE triples"] = int(len(vee))
    stats["VEE candidates"] = int(len(out[-1][0]))
    stats["seconds VEE lines"] = time.perf_counter() - clock
    clock = time.perf_counter()

    # E4: sorted quadruples of scene ids, deduplicated, solved as the reference does
    stats["E4 tuples"] = int(len(quads))
    quads = np.sort(ge[quads], axis=1)
    quads = unique_rows(quads)[0]
    if scope is not None:
        quads = quads[scope.nodes(np.full(len(quads), E4), quads)]
    stats["E4 quadruples"] = int(len(quads))
    out.append(_lines_in_chunks(_e4_lines, quads, (scene, line_of, line_solids), workers))
    stats["E4 candidates"] = int(len(out[-1][0]))
    stats["seconds E4 lines"] = time.perf_counter() - clock
    return _pack(out)


def passing_arcs(scene, edges, directions):
    """Each generator edge's directions of passing lines, as an arc of the circle of
    lines about it (module docstring, "Inner edges are passed").

    A line through an inner point of an edge with two faces, seen along the edge, is
    passed iff both faces lie on one side of the plane of the line and the edge
    (:mod:`viscx.geometry.tangency`): with w₁, w₂ the faces' unit directions
    perpendicular to the edge, inwards, the line's projected direction must not lie
    strictly between w₁ and w₂ (the angle θ < π they span), an arc of π - θ of the
    lines. Only where those two faces alone touch every inner point (the edge is clean,
    ``scene.contacts``); elsewhere every direction may pass.

    Parameters
    ----------
    edges : (n,) int
        Edge ids.
    directions : (n, 3) float
        The edges' directions as the scans use them (end minus start).

    Returns
    -------
    frame : (n, 2, 3) float
        Unit e₁ = w₁ and e₂ = b̂ × w₁ spanning the plane ⊥ the edge.
    arc : (n, 2) float
        Start (angle from e₁, in [0, π)) and length of the passing arc, grown by
        ``PASS_ANGLE`` on both sides; length π where any direction may pass.
    """
    c = scene.contacts
    edges = np.asarray(edges, dtype=np.int64)
    lo, hi = c.edge.offsets[edges], c.edge.offsets[edges + 1]
    two = (hi - lo == 2) & c.edge_clean[edges]
    first, normal = c.edge.first, c.edge.normal
    w = np.cross(normal, first)  # a half-plane spans from its first ray towards n × first
    w1, w2 = w[np.where(two, lo, 0)], w[np.where(two, lo + 1, 0)]
    b = directions / np.maximum(row_norms(directions), 1e-300)[:, None]
    e1 = w1 / np.maximum(row_norms(w1), 1e-300)[:, None]
    e2 = np.cross(b, e1)
    omega = np.arctan2(np.einsum("ij,ij->i", w2, e2), np.einsum("ij,ij->i", w2, e1))
    # crossing lines lie strictly between 0 and ω (mod π): (0, ω) if ω > 0, else (ω + π, π)
    arc = np.stack([np.where(omega > 0, omega, 0.0) - PASS_ANGLE, np.pi - np.abs(omega) + 2 * PASS_ANGLE], axis=1)
    arc[:, 0] %= np.pi
    arc[~(two & np.isfinite(omega) & (arc[:, 1] < np.pi)), 1] = np.pi
    return np.ascontiguousarray(np.stack([e1, e2], axis=1)), arc


def _scope_arrays(scope, gv, ge, ev, vx):
    """The scans' scope arguments (:func:`_scan_edge_pairs`): which generator edges and
    vertices (by position) are in scope, and the scope generators as segments (vertices
    without a scope edge through them as points). Without a scope every row is kept."""
    if scope is None:
        return (np.ones(len(ge), bool), np.ones(len(gv), bool), np.zeros((0, 3)), np.zeros((0, 3)))
    se, sv = scope.edges[ge], scope.node_vertices[gv]
    # (the vertices inside a scope edge lie on its segment)
    alone = scope.vertices[gv].copy()
    alone[ev[se].ravel()] = False
    a = np.concatenate([vx[ev[se, 0]], vx[alone]])
    b = np.concatenate([vx[ev[se, 1]], vx[alone]])
    return se, sv, np.ascontiguousarray(a), np.ascontiguousarray(b)


def _vee_lines(vee, scene, line_of, solids):
    """VEE candidates of canonical triples ``vee`` (n, 3) int (v, e1, e2), solved as
    the reference does; ``line_of`` (n_edges, 6) float: Plücker lines by edge id.
    Returns kind (m,), generators (m, 4) int, origins and directions (m, 3) float."""
    v, e1, e2 = vee[:, 0], vee[:, 1], vee[:, 2]
    d = line_through_point_and_two_lines(scene.vertices[v], line_of[e1], line_of[e2])
    fine = row_norms(d) > 0
    origin = scene.vertices[v]
    fine[fine] = _met_loosely(scene, origin[fine], d[fine], v[fine, None], vee[fine, 1:], solids)
    gens = np.stack([v, e1, e2, np.full_like(v, -1)], axis=1)[fine]
    return np.full(len(gens), VEE), gens, origin[fine], d[fine]


def _e4_lines(quads, scene, line_of, solids):
    """E4 candidates of sorted quadruples ``quads`` (n, 4) int, solved as the reference
    does (up to two lines each). Returns as :func:`_vee_lines`."""
    sol, valid, _ = lines_through_four_lines(line_of[quads])
    q_idx, s_idx = np.nonzero(valid)
    d, m = sol[q_idx, s_idx, :3], sol[q_idx, s_idx, 3:]
    origins = np.cross(d, m) / np.einsum("ij,ij->i", d, d)[:, None]
    ok = _met_loosely(scene, origins, d, np.zeros((len(d), 0), np.int64), quads[q_idx], solids)
    return np.full(ok.sum(), E4), quads[q_idx][ok], origins[ok], d[ok]


def _lines_in_chunks(solve, rows, args, workers):
    """``solve(rows_chunk, *args)`` over chunks of LINE_CHUNK rows on threads (numpy and
    the numba kernels release the GIL; each row is solved on its own), concatenated
    in order."""
    chunks = [rows[i : i + LINE_CHUNK] for i in range(0, len(rows), LINE_CHUNK)] or [rows]
    parts = map_chunks(lambda chunk: solve(chunk, *args), chunks, workers)
    return tuple(np.concatenate(x) for x in zip(*parts))


def _pack(out):
    if not out:
        return np.zeros(0, np.int8), np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    kind, gens, origins, dirs = (np.concatenate(x) for x in zip(*out))
    return kind.astype(np.int8), gens.astype(np.int64), origins, dirs


def validate_in_chunks(scene, kind, generators, origins, directions, chunk=VALIDATE_CHUNK):
    """:func:`viscx.skeleton.nodes.validate_candidates` over chunks of candidates
    (each candidate is judged on its own, so the result is the same; memory stays
    bounded), sorted once. Parameters as there."""
    parts = [
        nodes_among(scene, kind[i : i + chunk], generators[i : i + chunk], origins[i : i + chunk], directions[i : i + chunk])
        for i in range(0, len(kind), chunk)
    ]
    if not parts:
        return validate_candidates(scene, kind, generators, origins, directions)
    merged = Nodes(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in Nodes.__dataclass_fields__})
    return sort_nodes(merged)


def build_nodes(scene, quiet=True, workers=None, scope=None):
    """The nodes (V0) of a scene by the output-sensitive candidates.

    Parameters
    ----------
    scene : Scene
    quiet : bool
        No progress bars.
    workers : int, optional
        Threads for the hull scans.
    scope : viscx.skeleton.scope.Scope, optional
        Only the nodes with a generator in scope: the full build's nodes of those tuples,
        in its order (tests/test_scoped_mesh.py).

    Returns
    -------
    Nodes
        Equal to :func:`viscx.skeleton.reference.reference_nodes` (tests/test_fast_nodes.py).
    """
    kind, gens, origins, dirs = fast_candidates(scene, progress=lambda desc, total: bar(total, desc, quiet=quiet),
                                                workers=workers, scope=scope)
    return validate_in_chunks(scene, kind, gens, origins, dirs)
