"""Dynamic update of the complex after objects move, appear or vanish (Orti et al. §4.3):
linear in the zone.  :func:`move`, :func:`insert` and :func:`remove` are one
:func:`update` (a move is a removal and an insertion of the same object): the old complex
renumbered to the new scene's objects, then the zone of the changed objects K re-tested
and spliced.

Changing object K can only change

- the bitangents of K itself (all pairs (K, j)),
- the bitangents that K blocked before the move (a blocked candidate stays blocked unless
  its blocker moves: :func:`viscx.flatland.complex.blocker_table` keeps one blocker per
  candidate), and
- the vertices whose maximal free segment K meets before or after the move (K may start
  blocking them, or become / stop being the first object at one of their ends), and those
  whose line K touches (a rebuild may group it into a degenerate line: :func:`_meets_vertex`).

Only these candidates are re-tested (closed-form lines of their pairs, bit-identical to a
rebuild's; grid walks).  A re-tested vertex that comes back with the same line, objects,
sides, tail and head is the same vertex.  The others leave or enter the complex, and the
topology is spliced where they are — the *zone*:

1. incidences: the kept ones (already sorted along the tangency curves) and the new ones
   are merged by binary search (:func:`kernels.merge_ranks`);
2. edges: an edge whose two end incidences are kept and still consecutive keeps its
   tail, head, θ range and integrals, unless it lies on the moved object's tangency curve
   (its ∫u dθ moves with the object); the others are derived from their end vertices;
3. faces: the face components holding a slot of a vanished edge, with the new edges'
   slots, are re-glued by a union–find over their slots alone (a slot glued to a kept
   face's slot would have been in that face before the move: the zone is closed), and
   re-summed in the same slot order as a rebuild (bit-identical sums);
4. the stored arrays are renumbered by gathers (vertices by key, edges and faces in the
   order of a rebuild), the kept faces' boundary lists spliced with the new ones.

Python work is per changed element; what is O(scene) is row copies (the sorted arrays
spliced by :func:`kernels.splice_rows`, the kept faces' lists by :func:`kernels.csr_rows`)
and numpy gathers over the complex's arrays (and one scan of the blocker table).  The result equals a rebuild from
scratch, array by array (tests/flatland/test_flatland_dynamic.py).

A degenerate line in the zone (vertices resolved by a symbolic perturbation, ``v_tau``,
see :func:`viscx.flatland.complex.resolve_degenerate`) is re-scanned whole
(:func:`scan_line`): its free candidates are not all vertices (a row of m tips has
m(m − 1)/2 free pairs and about m vertices), so they are found from the line, not from the
vertices.  Its members then need not be in the blocker table: the line joins a registry
of re-scanned lines (``state["lines"]``), re-scanned whenever a moving object's disk meets
it.

Touching objects: the zone is re-tested in the opened scene (:meth:`Scene.opened`), the
fresh vertices carried to the contacts' limit lines (:func:`complex.close_contacts`); see
:func:`update` for when that is not local.

A complex read from a file carries the file's ``update`` group (:func:`update_arrays`):
the state and the blocker table by gathers.  From an older file without it, the state is
derived again from the stored vertices (O(m log m)), and without a blocker table every
candidate whose segment between its tangent points meets a changed object's disk is
re-tested (the pairs first pruned by the capsules around their bounding disks, O(n²)
arithmetic in numpy, then only their candidates computed).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from viscx.errors import ViscxError
from viscx.flatland import complex as C
from viscx.flatland import kernels as K
from viscx.flatland.scene import check_object_disjoint, make_scene, raise_along

VERTEX_FIELDS = ("v_key", "v_obj", "v_support", "v_side", "v_tail", "v_head", "v_theta", "v_tau", "v_p", "v_q",
                 "v_length", "v_seg")
# the fields that place a vertex in the topology (v_seg may change without changing it)
TOPOLOGY_FIELDS = ("v_obj", "v_support", "v_side", "v_tail", "v_head", "v_theta", "v_tau")


@dataclass
class MoveStats:
    """What a move recomputed, out of how many, and where the time went.

    ``local`` is False when the move rebuilt the complex (a file written before degenerate
    lines were resolved, or a complex without vertices); ``zone_*`` count the vertices
    that left / entered the complex, the edges derived anew and the face slots re-glued;
    ``seconds`` the CPU time per stage; ``pairs`` (P, 2) int64 the object pairs (a, b),
    b = −1 the sky, whose form factors were recomputed (a face of theirs was re-summed):
    every other entry of F_area / F_strings is the old one."""

    candidates_tested: int
    candidates_total: int
    faces_recomputed: int
    faces_total: int
    formfactors_recomputed: int
    formfactors_total: int
    local: bool = True
    why: str = ""
    zone_vertices_removed: int = 0
    zone_vertices_added: int = 0
    zone_edges: int = 0
    zone_slots: int = 0
    seconds: dict = field(default_factory=dict)
    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    def summary(self) -> str:
        how = ("zone: {} vertices out, {} in, {} edges and {} face slots re-derived".format(
            self.zone_vertices_removed, self.zone_vertices_added, self.zone_edges, self.zone_slots)
            if self.local else f"rebuilt from scratch ({self.why})")
        return (f"form factors recomputed: {self.formfactors_recomputed} of {self.formfactors_total} "
                f"(object pairs incl. the sky); faces re-summed: {self.faces_recomputed} of {self.faces_total}; "
                f"bitangent candidates re-tested: {self.candidates_tested} of {self.candidates_total}; {how}")


def _bounding_disk(scene, k):
    v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return c, float(np.max(np.hypot(*(v - c).T)) + scene.radius[k])


def move(cx: C.FlatComplex, k: int, dx: float, dy: float):
    """Move object k by (dx, dy) and update the complex in the zone (:func:`update`).

    Returns (new FlatComplex, MoveStats).  Raises ViscxError if k is not an object or the
    moved object would overlap another."""
    scene = cx.scene
    _check_index(scene, k)
    if not (np.isfinite(dx) and np.isfinite(dy)):
        raise ViscxError("the displacement must be finite")
    new_scene = scene.moved(k, dx, dy)
    old_c = scene.contacts()
    mine = (old_c[:, 0] == k) | (old_c[:, 1] == k)
    new_scene._contacts = _pairs_union(old_c[~mine], check_object_disjoint(new_scene, k))
    same = np.arange(scene.n)
    return update(cx, new_scene, [k], [k], same, curves=[k] if dx or dy else [])


def insert(cx: C.FlatComplex, objects):
    """Insert objects (JSON object dicts as in a scene file: circle, polygon, segment or
    open polyline, the last split into its pieces) after the scene's objects, and update
    the complex in their zone (:func:`update`).  An object without a name is named
    ``object<i>``, i its index in the new scene.

    Returns (new FlatComplex, MoveStats).  Raises ViscxError for a bad object, a name
    already used, or an overlap."""
    scene = cx.scene
    objects = [objects] if isinstance(objects, dict) else list(objects)
    objects = [dict(o, name=o.get("name", f"object{scene.n + i}")) if isinstance(o, dict) else o
               for i, o in enumerate(objects)]
    extra = make_scene(objects)
    clash = sorted(set(extra.names) & set(scene.names))
    if clash:
        raise ViscxError(f"an object is already named {clash[0]!r}; names must be unique")
    new_scene = scene.joined(extra)
    came = np.arange(scene.n, new_scene.n)
    new_scene._contacts = _pairs_union(scene.contacts(), extra.contacts() + scene.n,
                                       *[check_object_disjoint(new_scene, j) for j in came])
    return update(cx, new_scene, [], came, np.arange(scene.n))


def remove(cx: C.FlatComplex, k: int):
    """Remove object k (the objects after it move down one index, as in a scene file
    without it) and update the complex in its zone (:func:`update`).

    Returns (new FlatComplex, MoveStats).  Raises ViscxError if k is not an object or it
    is the last one."""
    scene = cx.scene
    _check_index(scene, k)
    if scene.n == 1:
        raise ViscxError("cannot remove the only object of the scene")
    objmap = np.arange(scene.n) - (np.arange(scene.n) > k)
    objmap[k] = -1
    new_scene = scene.selected(np.delete(np.arange(scene.n), k))
    old_c = scene.contacts()
    new_scene._contacts = objmap[old_c[(old_c[:, 0] != k) & (old_c[:, 1] != k)]].reshape(-1, 2)
    return update(cx, new_scene, [k], [], objmap)


def _check_index(scene, k):
    if not (0 <= k < scene.n):
        raise ViscxError(f"--object {k}: the scene has objects 0..{scene.n - 1}")


def _pairs_union(*pairs):
    """Sorted distinct (i, j) rows of several (c, 2) arrays."""
    return np.unique(np.concatenate([np.asarray(p, np.int64).reshape(-1, 2) for p in pairs]), axis=0).reshape(-1, 2)


def update(cx: C.FlatComplex, new_scene, gone, came, objmap, curves=None):
    """The complex of ``new_scene`` from ``cx``'s, re-deriving only the zone of the objects
    that changed: ``gone`` the objects of the old scene that moved or vanished, ``came``
    the objects of the new scene that moved or appeared (their edges are redone), ``objmap``
    (n_old,) the new index of every old object (−1: removed; a monotone map).  A move is
    gone = came = [k]; an insertion gone = [], came = the new objects; a removal gone =
    [k], came = [].

    Touching objects: the vertices are those of the opened scene (:meth:`Scene.opened`,
    every touching object eroded by γ = rel × the diagonal) carried to the contacts' limit
    lines (:func:`complex.close_contacts`), so the zone is re-tested in the opened scene;
    the objects whose erosion changes (they make or lose their only contact) join the
    changed objects.  Rebuilt instead (``MoveStats.local`` False, with the reason) when the
    opened scene itself changes globally: the diagonal changes (so does γ), the scene gains
    its first contact or loses its last, or the complex was opened with a fallback gap; and
    when the zone cannot be resolved locally (a degenerate line tilted by about its
    tolerance: the rebuild's chained grouping of lines sees one line where the zone's
    re-scan sees two).

    Returns (new FlatComplex, MoveStats)."""
    scene = cx.scene
    n = new_scene.n
    total = 2 * n * (n - 1)
    gone, came = np.asarray(gone, np.int64), np.asarray(came, np.int64)
    came0 = came
    if "v_tau" not in cx.arrays:  # written before degenerate lines were resolved
        return _rebuilt(cx, new_scene, total)
    if cx.n_vertices == 0 or n < 2:
        return _rebuilt(cx, new_scene, total, "a scene of one object before or after (no vertex)")
    if cx.state is None and cx.stored is not None:  # read from a file with its update group
        cx = state_from_update_arrays(cx, cx.stored)
    if cx.state is None:  # read from an older file: the state is derived again from the stored vertices
        cx = C.FlatComplex(scene=scene, eps=cx.eps, arrays=cx.arrays, state=C.derive(scene, cx.arrays)[1],
                           blockers=cx.blockers)
    opened = _opened_scenes(cx, new_scene, gone, came, objmap)
    if isinstance(opened, str):
        return _rebuilt(cx, new_scene, total, opened)
    work_old, work_new, gone, came, rel = opened
    try:
        return _update(cx, new_scene, work_old, work_new, gone, came, objmap, total, rel,
                       came if curves is None else np.union1d(curves, came[~np.isin(came, came0)]))
    except ViscxError as e:
        # a degenerate line the change tilts by about its tolerance is one line for the
        # rebuild's chained grouping but not for the zone's re-scan (and an opened scene
        # may be unresolvable at this gap, where the build tries others): rebuilt
        return _rebuilt(cx, new_scene, total, f"the zone could not be resolved locally: {str(e)[:60]}…")


def _opened_scenes(cx, new_scene, gone, came, objmap):
    """The scenes the zone is re-tested in, before and after: the scenes themselves, or
    with touching objects their opened scenes (only the changed objects and those whose
    erosion changes re-eroded; bit-identical to ``new_scene.opened(rel)``).  Returns
    (old, new, gone, came, rel) or, when the update cannot be local, the reason."""
    scene = cx.scene
    old_c, new_c = scene.contacts(), new_scene.contacts()
    if not (old_c.size or new_c.size):
        return scene, new_scene, gone, came, 0.0
    if not (old_c.size and new_c.size):
        return "touching objects: the scene gains its first contact or loses its last, which moves every vertex"
    rel, work_old = cx.state.get("open", (None, None))
    if rel is None:
        return "touching objects in a complex read from a file (the opened scene is not stored)"
    if rel != C.OPEN_RELS[0]:
        return "touching objects: the complex was opened with a fallback gap"
    diag = new_scene.diagonal()
    if diag != scene.diagonal():
        return "touching objects: the scene diagonal changed, and with it the gap γ of every contact"
    was = np.zeros(scene.n, bool)
    was[old_c.ravel()] = True
    now = np.zeros(new_scene.n, bool)
    now[new_c.ravel()] = True
    kept = np.nonzero(objmap >= 0)[0]
    flip = kept[was[kept] != now[objmap[kept]]]
    gone = np.union1d(gone, flip)
    came = np.union1d(came, objmap[flip])
    work_new = work_old.selected(kept)
    if n_new := new_scene.n - kept.size:
        work_new = work_new.joined(new_scene.selected(np.arange(new_scene.n - n_new, new_scene.n)))
    for j in came:
        s, e = new_scene.vert_start[j], new_scene.vert_start[j + 1]
        geo = new_scene.eroded(j, rel * diag) if now[j] else (new_scene.verts[s:e], new_scene.radius[j])
        work_new = work_new.replaced(j, *geo)
    for j in came:
        left = check_object_disjoint(work_new, j, eps=0.01 * rel * diag)
        if left.size:
            raise_along(new_scene, *left[0])
    work_new._contacts = np.zeros((0, 2), np.int64)
    return work_old, work_new, gone, came, rel


def _update(cx, new_scene, work_old, work_new, gone, came, objmap, total, rel, curves):
    """:func:`update` in the scenes ``work_old`` / ``work_new`` (the opened scenes when
    objects touch, else the scenes)."""
    scene = cx.scene
    n_old, n = scene.n, new_scene.n
    clock = _Clock()
    V_old = cx.arrays
    # -- 1. the candidates to re-test (in the old numbering)
    own_v = np.isin(V_old["v_obj"], gone).any(axis=1)
    th, u, sin, cos = _working_lines(work_old, V_old, rel)
    disks = [_bounding_disk(work_old, j) for j in gone] + [_bounding_disk(work_new, j) for j in came]
    near = np.zeros(th.shape[0], bool)
    for c, r in disks:
        near |= np.abs(-sin * c[0] + cos * c[1] - u) <= r + 10 * cx.eps
    retest_v = near & ~own_v
    if not rel:  # a simple vertex changes only where a changed object meets its free segment or touches its line
        simple = np.nonzero(retest_v & (V_old["v_tau"] == 0.0))[0]
        stays = ~_meets_vertex(V_old, simple, th, u, sin, cos, [(work_old, j) for j in gone] +
                               [(work_new, j) for j in came], 10 * cx.eps, C.line_tol(work_new))
        retest_v[simple[stays]] = False
    if cx.blockers is not None:
        hit = np.zeros(cx.blockers.shape[0], bool)
        for j in gone:  # (compared as int32: np.isin would convert the 4n² table to int64 first)
            hit |= cx.blockers == np.int32(j)
        blocked = np.flatnonzero(hit)
    else:  # no blocker table (read from a file): every candidate whose segment meets a gone object
        blocked = [np.zeros(0, np.int64)]
        for c, r in disks[:gone.size]:
            some = C.candidates(work_old, _pairs_near(work_old, c, r + 10 * cx.eps))
            p_, q_ = C.tangent_points(work_old, some)
            blocked.append(some["key"][_segment_distance(p_, q_, c) <= r + 10 * cx.eps])
        blocked = np.unique(np.concatenate(blocked))
    b_pair = blocked // 4
    blocked = blocked[~np.isin(b_pair // n_old, gone) & ~np.isin(b_pair % n_old, gone)]
    # a vertex among the candidates re-tested as blocked ones (without a blocker table: those
    # whose segment meets a gone object) is re-done with them
    at = np.minimum(np.searchsorted(V_old["v_key"], blocked), V_old["v_key"].shape[0] - 1)
    retest_v[at[V_old["v_key"][at] == blocked]] = True
    # degenerate lines in the zone: those of its resolved vertices, and the lines re-scanned
    # by earlier moves (their blocked members are not in the blocker table) that it meets
    tol = C.line_tol(work_new)
    reg_th, reg_u = cx.state.get("lines", (np.zeros(0), np.zeros(0)))
    reg_near = np.zeros(reg_th.shape[0], bool)
    for c, r in disks:
        reg_near |= np.abs(-np.sin(reg_th) * c[0] + np.cos(reg_th) * c[1] - reg_u) <= r + 10 * cx.eps
    deg = (retest_v | own_v) & (V_old["v_tau"] != 0.0)
    lines_th, lines_u = _distinct_lines(np.concatenate([th[deg], reg_th[reg_near]]),
                                        np.concatenate([u[deg], reg_u[reg_near]]), tol)
    if np.any(C.near_degenerate(work_new, lines_th, lines_u, tol)):  # issue #25: grouped beyond the line alone
        raise ViscxError("a near-degenerate line in the zone (an object within the tolerance of it)")
    on_line = _on_lines(th, u, lines_th, lines_u, tol)
    retest_v |= on_line & ~own_v
    # -- the old complex in the new numbering
    V_old, state, blockers = _renumbered(cx, new_scene, objmap)
    blocked = _new_keys(blocked, objmap, n_old, n)
    pair_of = V_old["v_key"] // 4
    own_pairs = [np.zeros((0, 2), np.int64)]
    for j in came:
        others = np.delete(np.arange(n), j)
        own_pairs.append(np.stack([np.minimum(others, j), np.maximum(others, j)], 1))
    own_pairs = np.concatenate(own_pairs)
    pid = np.unique(np.concatenate([own_pairs[:, 0] * n + own_pairs[:, 1], blocked // 4, pair_of[retest_v & ~on_line]]))
    cand = C.candidates(work_new, np.stack([pid // n, pid % n], 1).astype(np.int64))
    redo = np.concatenate([blocked, V_old["v_key"][retest_v & ~on_line]])
    todo = np.isin(cand["a"], came) | np.isin(cand["b"], came) | np.isin(cand["key"], redo)
    grid = K.build_grid(work_new.bounding_boxes())
    cls = C.classify(work_new, cand, cx.eps, todo=todo, grid=grid)
    if np.any(cls[7] & cls[0] & todo):  # a near-degenerate line: its group reaches beyond the zone
        raise ViscxError("a near-degenerate line in the zone (a line within the tolerance of a third object)")
    fresh = C.vertices_from(work_new, cand, cls)
    if lines_th.size:  # the degenerate lines are re-scanned whole, not from their candidates
        fth = fresh["v_theta"]
        fu = np.einsum("ij,ij->i", np.stack([-np.sin(fth), np.cos(fth)], 1), fresh["v_p"])
        off = ~_on_lines(fth, fu, lines_th, lines_u, tol)
        fresh = {name: arr[off] for name, arr in fresh.items()}
    fresh = C.resolve_degenerate(work_new, fresh)
    if lines_th.size:
        scanned = [scan_line(work_new, t_, u_, cx.eps, tol, grid) for t_, u_ in zip(lines_th, lines_u)]
        fresh = {name: np.concatenate([fresh[name]] + [x[name] for x in scanned]) for name in VERTEX_FIELDS}
        o = np.argsort(fresh["v_key"], kind="stable")
        fresh = {name: arr[o] for name, arr in fresh.items()}
    if rel:  # carried to the contacts' limit lines
        fresh = C.close_contacts(new_scene, fresh)
    if blockers is not None:
        blockers[cand["key"][todo]] = cls[6][todo]
    clock.lap("candidates")
    # -- 2. the new vertex set, merged by key; re-tested vertices that did not change stay
    V, vmap, added = _merge_vertices(V_old, fresh, retest_v | own_v)
    old_bb, new_bb = scene.bounding_boxes(), new_scene.bounding_boxes()
    if not (np.array_equal(old_bb[:, :2].min(0), new_bb[:, :2].min(0))
            and np.array_equal(old_bb[:, 2:].max(0), new_bb[:, 2:].max(0))):
        # sky ends are clipped to the scene box, which the update changed
        V["v_seg"] = C.clip_sky_ends(new_scene, V["v_theta"], V["v_p"], V["v_q"], V["v_tail"], V["v_head"], V["v_seg"])
    clock.lap("vertices")
    out, st, zone = _splice_topology(new_scene, state, V, vmap, added, curves)
    V.update(out)
    clock.lap("topology")
    st["lines"] = _distinct_lines(np.concatenate([reg_th, lines_th]), np.concatenate([reg_u, lines_u]), tol)
    if rel:
        st["open"] = (rel, work_new)
    new = C.FlatComplex(scene=new_scene, eps=cx.eps, arrays=V, state=st, blockers=blockers)
    stats = _stats(new, zone["faces"], int(todo.sum()), total, zone["lost"])
    stats.zone_vertices_removed = int(np.sum(vmap < 0))
    stats.zone_vertices_added = int(added.size)
    stats.zone_edges, stats.zone_slots = zone["edges"], zone["slots"]
    stats.seconds = clock.laps
    return new, stats


def _working_lines(work, V, rel):
    """(θ, u, sin θ, cos θ) of every vertex's line in the scene the zone is re-tested in: the stored
    line, or with touching objects the opened scene's (θ of the opened scene, u from its
    first support disk: n·v_j + σ r, σ = +1 for an object on the right)."""
    if not rel:
        th = V["v_theta"]
        sin, cos = np.sin(th), np.cos(th)
        return th, -sin * V["v_p"][:, 0] + cos * V["v_p"][:, 1], sin, cos
    th = V["v_theta_sort"]
    sin, cos = np.sin(th), np.cos(th)
    j1, k1 = V["v_support"][:, 0], V["v_obj"][:, 0]
    v = work.verts[j1]
    return th, -sin * v[:, 0] + cos * v[:, 1] + (2.0 * V["v_side"][:, 0] - 1.0) * work.radius[k1], sin, cos


def _meets_vertex(V, idx, th, u, sin, cos, objects, pad, tol):
    """(len(idx),) bool: the simple vertices ``idx`` that one of ``objects`` ((scene, k)
    pairs: the changed objects before and after) may change.  A vertex is the bitangent
    of its two objects with its maximal free segment (``v_seg``, a ray at a sky end); an
    object that neither comes within ``pad`` of that segment nor touches the vertex's line
    leaves it as it is: the segment stays free, its tail and head stay the first objects
    beyond its ends.  Touching is tested to a margin that covers the degenerate-line
    grouping of a rebuild (:func:`complex.degenerate_lines`: a line joins another whose
    objects touch it within JOIN × tol at its two tangent points, so the two lines part by
    at most about JOIN tol (1 + 2 D / |pq|) at a distance D along it), four times over.
    The vertex's line (θ, u) is the stored one (no touching objects).

    Replaces the test of the whole line against the object's disk, which re-tested every
    vertex whose line, far beyond its free segment, passes near the object (in a row of
    panels, the lines under the panels to the ground's corner: half of a move's walks)."""
    if idx.size == 0:
        return np.zeros(0, bool)
    d = np.stack([cos[idx], sin[idx]], 1)
    nrm = np.stack([-sin[idx], cos[idx]], 1)
    p = V["v_p"][idx]
    seg = V["v_seg"][idx]
    L = np.abs(V["v_length"][idx])
    t0 = np.where(V["v_tail"][idx] < 0, -np.inf, np.einsum("ij,ij->i", seg[:, :2] - p, d))
    t1 = np.where(V["v_head"][idx] < 0, np.inf, np.einsum("ij,ij->i", seg[:, 2:] - p, d))
    out = np.zeros(idx.size, bool)
    for scene, k in objects:
        v, r = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]], scene.radius[k]
        c, rad = _bounding_disk(scene, k)
        tc = np.einsum("ij,ij->i", c - p, d)
        w = nrm @ c - u[idx]
        gap = np.maximum(np.maximum(t0 - tc, tc - t1), 0.0)
        # meeting the segment: the object reaches across the line (its support values
        # along the normal on both sides of u) and its bounding disk reaches the segment
        proj = nrm @ v.T
        lo, hi = proj.min(axis=1) - r, proj.max(axis=1) + r
        out |= (np.hypot(w, gap) <= rad + pad) & (lo - pad <= u[idx]) & (u[idx] <= hi + pad)
        # touching the line anywhere
        far = np.maximum(np.abs(tc), np.abs(tc - L)) + rad
        margin = 4.0 * C.JOIN * tol * (1.0 + 2.0 * far / np.maximum(L, 1e-300)) + pad
        out |= (np.abs(u[idx] - lo) <= margin) | (np.abs(u[idx] - hi) <= margin)
    return out


def _new_keys(keys, objmap, n_old, n):
    """Candidate keys (pair (i, j) · 4 + kind) in the new numbering: i, j → objmap[i],
    objmap[j] (monotone, so sorted keys stay sorted); −1 where an object was removed."""
    pair, kind = keys // 4, keys % 4
    i, j = objmap[pair // n_old], objmap[pair % n_old]
    return np.where((i >= 0) & (j >= 0), (i * n + j) * 4 + kind, -1)


def _renumbered(cx, new_scene, objmap):
    """The vertex fields, the state and the blocker table of ``cx`` in the new numbering
    of objects (``objmap``; a removed object becomes −2 as a tail or head, which no vertex
    of the new scene has; as an index, −2 picks the last object's digest, harmless: its
    faces are all in the zone).  Only the vertex keys change when objects are appended."""
    n_old, n = cx.scene.n, new_scene.n
    fields = VERTEX_FIELDS + (("v_theta_sort",) if "v_theta_sort" in cx.arrays else ())
    V = {name: cx.arrays[name] for name in fields}
    st, blockers = cx.state, cx.blockers
    if n == n_old:
        return V, st, None if blockers is None else blockers.copy()
    V["v_key"] = _new_keys(V["v_key"], objmap, n_old, n)
    kept = np.nonzero(objmap >= 0)[0]
    lut = np.append(np.where(objmap >= 0, objmap, -2), -1)  # lut[-1]: the sky stays
    if blockers is not None:  # rows and columns of the kept objects' pairs, by blocks of consecutive ones
        old = blockers.reshape(n_old, n_old, 4)
        tab = np.full((n, n, 4), -1, np.int32)
        runs = np.split(kept, np.nonzero(np.diff(kept) > 1)[0] + 1)
        for ri in runs:
            for rj in runs:
                tab[objmap[ri[0]]:objmap[ri[-1]] + 1, objmap[rj[0]]:objmap[rj[-1]] + 1] = \
                    old[ri[0]:ri[-1] + 1, rj[0]:rj[-1] + 1]
        if kept.size < n_old:  # a removal: blockers renumbered (those it blocked are re-tested)
            # lut[tab] by int32 arithmetic in place (the gather would copy the 4n² table as intp)
            gone_objs = np.nonzero(objmap < 0)[0]
            was = tab.copy()
            for r in gone_objs:
                tab -= (was > r).view(np.int8)
            for r in gone_objs:
                tab[was == r] = -2
        blockers = tab.reshape(-1).astype(np.int32, copy=False)
    if np.array_equal(objmap, np.arange(n_old)):
        return V, st, blockers
    obj = lambda a: lut[a]  # noqa: E731
    V["v_obj"], V["v_tail"], V["v_head"] = obj(V["v_obj"]), obj(V["v_tail"]), obj(V["v_head"])
    size = np.diff(cx.scene.vert_start)
    gone_v = np.repeat(objmap < 0, size)
    sup = np.cumsum(~gone_v) - 1  # support points keep their order
    V["v_support"] = np.where(gone_v[V["v_support"]], -1, sup[V["v_support"]])
    st = dict(st)
    st["s_cur"] = 2 * lut[st["s_cur"] // 2] + st["s_cur"] % 2
    st["tail"], st["head"] = obj(st["tail"]), obj(st["head"])
    ct, ch = st["c_tail"], st["c_head"]
    st["c_tail"] = np.where(ct >= 0, lut[np.maximum(ct, 0)], ct)
    st["c_head"] = np.where(ch >= 0, lut[np.maximum(ch, 0)], ch)
    return V, st, blockers  # (face signatures digest tail and head by name, not by id: kept)


def _segment_distance(a, b, c):
    """(N,) distance from the point c (2,) to the segments a → b (N, 2)."""
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", c - a, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * ab - c).T)


def _pairs_near(scene, c, r, chunk=1 << 22):
    """(P, 2) int64 object pairs (i < j) a candidate of which may cut the disk (c, r): a
    common tangent's segment between its tangent points lies in the hull of both objects,
    inside the capsule of radius max(ρ_i, ρ_j) around the segment between the centres of
    their bounding disks (c_i, ρ_i).  O(n²) arithmetic in numpy, in chunks of rows."""
    bb = scene.bounding_boxes()
    cen = 0.5 * (bb[:, :2] + bb[:, 2:])
    rad = 0.5 * np.hypot(bb[:, 2] - bb[:, 0], bb[:, 3] - bb[:, 1])
    n = scene.n
    out = []
    rows = max(1, chunk // max(n, 1))
    for i0 in range(0, n, rows):
        ii, jj = np.nonzero(np.triu(np.ones((min(rows, n - i0), n), bool), i0 + 1))
        ii += i0
        near = _segment_distance(cen[ii], cen[jj], c) <= r + np.maximum(rad[ii], rad[jj])
        out.append(np.stack([ii[near], jj[near]], 1))
    return np.concatenate(out).astype(np.int64) if out else np.zeros((0, 2), np.int64)


def _distinct_lines(th, u, tol):
    """One (θ, u) per distinct line (copies within the tolerances merged)."""
    g = C.line_groups(th, u, tol)
    first = np.unique(g, return_index=True)[1]
    return th[first], u[first]


def _on_lines(th, u, lth, lu, tol):
    """(N,) bool: the lines (θ, u) that are one of the lines (lth, lu) (canonical θ)."""
    out = np.zeros(th.shape[0], bool)
    for t_, u_ in zip(lth, lu):
        out |= (np.abs(th - t_) <= C.TOL_THETA) & (np.abs(u - u_) <= tol)
    return out


def scan_line(scene, th, u, eps, tol, grid):
    """The vertices on the degenerate line (θ, u), from the line alone: the objects touching
    it (support value u on one side) and those crossing it (deeper than eps) split it into
    maximal free segments; the entries of each are resolved like a rebuild resolves the
    group of its free candidates (:func:`complex.resolve_entries`), θ, tail, head and the
    segment's ends taken from its lowest-key candidate, the candidates of the vertices'
    pairs looked up by their objects and sides.  A segment with one pair of point contacts
    gives that pair's bitangent as a simple vertex.  O(n) numpy plus O(entries) Python.

    Returns vertex arrays (the fields of ``VERTEX_FIELDS``), sorted by key."""
    d = np.array([np.cos(th), np.sin(th)])
    nrm = np.array([-d[1], d[0]])
    starts = scene.vert_start[:-1]
    proj = scene.verts @ nrm
    hi = np.maximum.reduceat(proj, starts) + scene.radius
    lo = np.minimum.reduceat(proj, starts) - scene.radius
    codes = np.sort(np.concatenate([2 * np.nonzero(np.abs(hi - u) <= tol)[0] + C.R,
                                    2 * np.nonzero(np.abs(lo - u) <= tol)[0] + C.L]))
    o = u * nrm
    hk, ti, to = K.line_hits(o[0], o[1], d[0], d[1], eps, scene.kind, scene.vert_start, scene.verts, scene.radius)
    so = np.argsort(ti)
    hk, to = hk[so], to[so]
    pos, pos_b = C.contacts(scene, codes, d, nrm, tol)[:2]
    seg = np.searchsorted(to, pos)
    rows = []
    for s_ in np.unique(seg):
        ent = codes[seg == s_]
        objs = np.unique(ent // 2)
        if objs.size < 2:
            continue
        point = bool(np.all(pos[seg == s_] == pos_b[seg == s_]))
        rows.extend(_segment_vertices(scene, ent, objs, point, th, u, eps, tol, grid))
    if not rows:
        return {name: np.zeros((0,) + shape, dtype) for name, (dtype, shape) in _VERTEX_LAYOUT.items()}
    out = {name: np.concatenate([r[name] for r in rows]) for name in VERTEX_FIELDS}
    o = np.argsort(out["v_key"], kind="stable")
    return {name: arr[o] for name, arr in out.items()}


_VERTEX_LAYOUT = dict(v_key=(np.int64, ()), v_obj=(np.int64, (2,)), v_support=(np.int64, (2,)), v_side=(np.int8, (2,)),
                      v_tail=(np.int64, ()), v_head=(np.int64, ()), v_theta=(float, ()), v_tau=(float, ()),
                      v_p=(float, (2,)), v_q=(float, (2,)), v_length=(float, ()), v_seg=(float, (4,)))


def _pair_candidates_on(scene, pairs, th, u, tol):
    """The candidates of object pairs (P, 2) and which of them lie on the line (θ, u), with
    their objects and sides in the order along the line (k1 first)."""
    cand = C.candidates(scene, pairs)
    p, q = C.tangent_points(scene, cand)
    ct = cand["theta"]
    on = (np.abs(ct - th) <= C.TOL_THETA) & (np.abs(-np.sin(ct) * p[:, 0] + np.cos(ct) * p[:, 1] - u) <= tol)
    first = np.einsum("ij,ij->i", q - p, np.stack([np.cos(ct), np.sin(ct)], 1)) >= 0
    k1 = np.where(first, cand["a"], cand["b"]); k2 = np.where(first, cand["b"], cand["a"])
    s1 = np.where(first, cand["side_a"], cand["side_b"]); s2 = np.where(first, cand["side_b"], cand["side_a"])
    return cand, on, (2 * k1 + s1) * (2 * scene.n) + 2 * k2 + s2


def _segment_vertices(scene, ent, objs, point, th, u, eps, tol, grid):
    """Vertex rows of one maximal free segment of a degenerate line (see :func:`scan_line`)."""
    # the lowest-key free candidate on the segment (the rebuild's first member of the group)
    cand, on, _ = _pair_candidates_on(scene, np.array([[objs[0], objs[1]]], np.int64), th, u, tol)
    i0 = np.nonzero(on)[0][:1]
    one = {name: arr[i0] for name, arr in cand.items()}
    first = C.vertices_from(scene, one, C.classify(scene, one, eps, grid=grid))
    if first["v_key"].size == 0:
        return []
    n_members = ent.size * (ent.size - 1) // 2 - (ent.size - objs.size)
    if n_members == 1 and point:
        first["v_tau"] = np.zeros(1)
        return [first]
    n2 = 2 * scene.n
    want, row = C.resolve_entries(scene, ent, float(first["v_theta"][0]), int(first["v_tail"][0]),
                                  int(first["v_head"][0]), first["v_seg"][0, :2], first["v_seg"][0, 2:], tol,
                                  lambda ci, cj: ci * n2 + cj)
    if want.size == 0:
        return []
    pairs = np.stack([want // n2 // 2, want % n2 // 2], 1)
    cand, on, code = _pair_candidates_on(scene, np.sort(pairs, axis=1).astype(np.int64), th, u, tol)
    hit = (on & (code == np.repeat(want, 4))).reshape(-1, 4)
    if np.any(hit.sum(axis=1) != 1):
        raise ViscxError("a degenerate line could not be resolved (a common tangent was not found as a candidate)")
    sel = 4 * np.arange(want.size) + np.argmax(hit, axis=1)
    row["v_key"] = cand["key"][sel]
    row["v_obj"] = pairs.astype(np.int64)
    row["v_side"] = np.stack([(want // n2) % 2, want % 2], 1).astype(np.int8)
    row["v_tail"] = row["v_tail"].astype(np.int64)
    row["v_head"] = row["v_head"].astype(np.int64)
    return [row]


class _Clock:
    """CPU seconds per named stage."""

    def __init__(self):
        self.laps, self.t = {}, time.process_time()

    def lap(self, name):
        t = time.process_time()
        self.laps[name] = t - self.t
        self.t = t


def _rebuilt(cx, new_scene, total, why="a file written before degenerate lines were resolved (no vertices/tau)"):
    new = C.build(new_scene, eps=cx.eps)
    stats = _stats(new, np.ones(new.n_faces, bool), total, total)
    stats.local = False
    stats.why = why
    return new, stats


def _spliced(old, keep, ins, new):
    """:func:`kernels.splice_rows` of (N, ...) arrays: the rows of ``old`` where ``keep``,
    with the rows of ``new`` placed after the first ``ins`` kept ones."""
    w = int(np.prod(old.shape[1:]))
    out = K.splice_rows(np.ascontiguousarray(old).reshape(-1, w), keep,
                        np.asarray(ins, np.int64), np.ascontiguousarray(new, old.dtype).reshape(-1, w))
    return out.reshape((-1,) + old.shape[1:])


def _merge_vertices(V_old, fresh, redone):
    """The vertices after the move: the old ones not re-done and the fresh ones, by key.

    Returns (V, vmap, added): vmap (m_old,) the new index of each old vertex that stays in
    the topology (a re-done vertex whose fresh copy has the same topology fields stays),
    −1 for one that left; added the new indices of the vertices that entered."""
    keep = np.nonzero(~redone)[0]
    fk = fresh["v_key"]
    fields = tuple(V_old)
    V = {}
    fidx = np.searchsorted(V_old["v_key"][keep], fk) + np.arange(fk.size)
    m = keep.size + fk.size
    kidx = np.arange(keep.size) + np.searchsorted(fidx - np.arange(fk.size), np.arange(keep.size), side="right")
    for name in fields:
        V[name] = _spliced(V_old[name], ~redone, fidx - np.arange(fk.size), fresh[name])
    vmap = np.full(V_old["v_key"].shape[0], -1, np.int64)
    vmap[keep] = kidx
    # a re-done vertex found again, unchanged
    rd = np.nonzero(redone)[0]
    j = np.searchsorted(fk, V_old["v_key"][rd])
    j = np.minimum(j, max(fk.size - 1, 0))
    same = (fk.size > 0) & (fk[j] == V_old["v_key"][rd]) if fk.size else np.zeros(rd.size, bool)
    for name in TOPOLOGY_FIELDS + (("v_theta_sort",) if "v_theta_sort" in fields else ()):
        a, b = V_old[name][rd], fresh[name][j] if fk.size else V_old[name][rd]
        eq = a == b
        same &= eq.all(axis=tuple(range(1, eq.ndim)))
    vmap[rd[same]] = fidx[j[same]]
    entered = np.ones(fk.size, bool)
    entered[j[same]] = False
    return V, vmap, fidx[entered]


def _splice_topology(scene, old, V, vmap, added, curves):
    """The topology state and stored arrays after the vertices changed (see the module
    docstring); ``curves`` the objects whose tangency curves' edges are all redone.  Returns (arrays, state, zone sizes)."""
    m_old, m = vmap.shape[0], V["v_key"].shape[0]
    O = C.occurrences(V)
    N_old = old["s_occ"].shape[0]
    # -- incidences: the kept ones in order, renumbered; the new ones merged in
    v_old, o_old = old["s_occ"] % m_old, old["s_occ"] >= m_old
    kept_inc = vmap[v_old] >= 0
    kpos = np.nonzero(kept_inc)[0]
    k_occ = vmap[v_old[kpos]] + o_old[kpos] * m
    cur, th, tau, occ, role = C.incidences(O, np.concatenate([added, added + m]))
    ths = O["THS"][occ]  # the order along the curves (the opened scene's θ at contacts)
    o = np.lexsort((occ, tau, ths, cur))
    cur, th, ths, tau, occ, role = cur[o], th[o], ths[o], tau[o], occ[o], role[o]
    old_ths = old.get("s_ths", old["s_th"])
    ins = K.merge_ranks(old["s_cur"][kpos], old_ths[kpos], old["s_tau"][kpos], k_occ, cur, ths, tau, occ)
    N = kpos.size + cur.size
    at_kept = np.arange(kpos.size) + np.cumsum(np.bincount(ins, minlength=kpos.size + 1))[:kpos.size]
    st = {}
    parts = [("s_occ", vmap[v_old] + o_old * m, occ), ("s_role", old["s_role"], role), ("s_cur", old["s_cur"], cur),
             ("s_th", old["s_th"], th), ("s_tau", old["s_tau"], tau)]
    if "s_ths" in old:
        parts.append(("s_ths", old_ths, ths))
    for name, old_vals, new_vals in parts:
        st[name] = _spliced(old_vals, kept_inc, ins, new_vals)
    C.link(st, 2 * m)
    newpos = np.full(N_old, -1, np.int64)
    newpos[kpos] = at_kept
    # -- edges: kept when both ends are kept and still consecutive, and not on the moved
    # object's tangency curves: their ∫u dθ follows the object (u shifts by the move) even
    # when their end vertices come back unchanged (a move too small to change any θ)
    nxt_old = newpos[old["nxt"][kpos]]
    surv_old = kpos[(nxt_old >= 0) & (nxt_old == st["nxt"][at_kept]) & ~np.isin(old["s_cur"][kpos] // 2, curves)]
    surv = newpos[surv_old]
    fresh_e = np.ones(N, bool)
    fresh_e[surv] = False
    pe = np.nonzero(fresh_e)[0]
    tmp = {}
    C.edge_attributes(scene, O, st, pe, tmp)
    for name in ("tail", "head", "th0", "th1", "I", "arc"):  # the kept incidences' edges, the fresh ones redone
        arr = _spliced(old[name], kept_inc, ins, np.zeros(cur.size, old[name].dtype))
        arr[pe] = tmp[name]
        st[name] = arr
    # -- faces: the old components holding a slot of a vanished edge form the zone
    dead = np.ones(N_old, bool)
    dead[surv_old] = False
    L_old = old["c_tail"].shape[0]
    in_zone = np.zeros(L_old + 1, bool)
    in_zone[np.take(old["comp"].reshape(-1, 3), np.nonzero(dead)[0], axis=0)] = True
    # L_old: 'to label' (the sentinel is in the zone), for the slots of the fresh edges
    comp = _spliced(old["comp"].reshape(-1, 3), kept_inc, ins, np.full((cur.size, 3), L_old, np.int64))
    comp[pe] = L_old
    in_zone[L_old] = True
    comp = comp.ravel()
    zslots = np.nonzero(in_zone[comp])[0]
    zedges = zslots // 3
    zedges = zedges[np.append(zedges[:1] >= 0, zedges[1:] != zedges[:-1])]
    zocc = np.unique(np.concatenate([st["s_occ"][zedges], st["s_occ"][st["nxt"][zedges]]]))
    X, Y, Z, W, _ = C.vertex_edges(O, st, zocc)
    ua, ub = C.glue_pairs(X, Y, Z, W)
    # a slot is in the zone iff its component is; its index among zslots from a table
    # left uninitialised elsewhere (read only at zone slots: no O(slots) fill)
    ina, inb = in_zone[comp[ua]], in_zone[comp[ub]]
    at = np.empty(comp.size, np.int64)
    at[zslots] = np.arange(zslots.size)
    ia, ib = np.where(ina, at[ua], 0), np.where(inb, at[ub], 0)
    if np.any(ina != inb):  # cannot happen (see the module docstring): a bug, not an input error
        raise RuntimeError("flatland move: the zone of the update is not closed under the vertex gluing")
    g = coo_matrix((np.ones(int(ina.sum())), (ia[ina], ib[ina])), shape=(zslots.size, zslots.size))
    nlab, lab = connected_components(g, directed=False)
    comp[zslots] = L_old + lab
    st["comp"] = comp
    six, sgn = C.six_faces(O, comp, zocc, X, Y, Z)
    six = np.where(six >= L_old, six - L_old, -1)
    new_attr = {}
    C.comp_attributes(scene, O, st, zslots, lab, nlab, six, sgn, zocc, new_attr)
    keep_lab = ~in_zone[:L_old]
    # labels without slots (left by earlier updates, until compacted) keep stale slots
    live = keep_lab & (np.bincount(old["comp"], minlength=L_old) > 0)
    remap_slot = lambda s: 3 * newpos[s // 3] + s % 3  # noqa: E731
    for name, vals in new_attr.items():
        base = old[name].copy()
        if name == "c_minslot":
            base[live] = remap_slot(base[live])
        st[name] = np.concatenate([base, vals])
    # -- the kept faces' boundary lists, renumbered
    kf = keep_lab[old["face_label"]]
    st["face_label"] = old["face_label"][kf]
    kf_rows = np.nonzero(kf)[0]
    st["fe_start"], st["fe_packed"] = K.csr_rows(old["fe_start"], old["fe_packed"], kf_rows, newpos, 2)
    st["fv_start"], st["fv_packed"] = K.csr_rows(old["fv_start"], old["fv_packed"], kf_rows, vmap, 3)
    out = C.canonical(scene, V, O, st, L_old + np.arange(nlab), zslots, zocc)
    faces = st["face_label"] >= L_old
    if st["c_tail"].shape[0] > 2 * st["face_label"].shape[0] + 2 * nlab:
        _compact(st)  # amortised: when dead labels outnumber the live ones
    # the faces that left (their pairs' form factors are recomputed too, if only to 0)
    lost = old["face_label"][~kf]
    lost = np.stack([old["c_tail"][lost], old["c_head"][lost]], 1)
    return out, st, dict(faces=faces, edges=int(pe.size), slots=int(zslots.size), lost=lost)


def _compact(st):
    """Drop dead component labels (those of the zone before the move), renumbering comp,
    c_* and face_label."""
    comp = st["comp"]
    alive = np.zeros(st["c_tail"].shape[0], bool)
    alive[comp] = True
    new_id = np.cumsum(alive) - 1
    st["comp"] = new_id[comp]
    for name in [k for k in st if k.startswith("c_")]:
        st[name] = st[name][alive]
    st["c_twin"] = new_id[st["c_twin"]]
    st["face_label"] = new_id[st["face_label"]]


def _pair_ids(f_pair, n):
    a = np.where(f_pair[:, 0] < 0, n, f_pair[:, 0])
    b = np.where(f_pair[:, 1] < 0, n, f_pair[:, 1])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return lo * (n + 1) + hi


def _stats(new, recomputed, tested, total, lost=None):
    """MoveStats of a new complex whose faces ``recomputed`` (F,) bool were re-summed;
    ``lost`` (L, 2): the (tail, head) of the old faces that left (−2: a removed object)."""
    n = new.scene.n
    ok = new.f_bounded & ~((new.f_pair[:, 0] < 0) & (new.f_pair[:, 1] < 0))
    pid = _pair_ids(new.f_pair, n)[ok]
    seen = np.zeros((n + 1) ** 2, bool)
    seen[pid] = True
    again = np.zeros((n + 1) ** 2, bool)
    again[pid[recomputed[ok]]] = True
    if lost is not None:
        lost = lost[np.all(lost >= -1, axis=1) & np.any(lost >= 0, axis=1)]
        again[_pair_ids(lost, n)] = True
    lo, hi = np.divmod(np.nonzero(again)[0], n + 1)
    pairs = np.stack([lo, np.where(hi == n, -1, hi)], 1)
    return MoveStats(pairs=pairs, candidates_tested=tested, candidates_total=total,
                     faces_recomputed=int(recomputed[ok].sum()), faces_total=int(ok.sum()),
                     formfactors_recomputed=int(again.sum()), formfactors_total=int(seen.sum()))


# ----------------------------------------------------------------------------- the update state in files
def update_arrays(cx: C.FlatComplex) -> dict | None:
    """What a local update needs beyond the stored arrays, for the ``update`` group of a
    file (docs/format.md), or None without a state.

    The topology's state on the double cover, canonical — equal for an updated complex and
    a rebuilt one: ``incidence`` (4m,) the incidences in their order along the tangency
    curves (id occ + role · 2m, occ = v or m + v for the reversed line), per incidence the
    edge starting there: ``tail``, ``head``, ``th0``, ``th1``, ``integral`` (∫u dθ),
    ``arclength``; ``slot_face`` (12m,) the face of each of its three slots as 2·f (the
    face as stored) or 2·f + 1 (its twin, the reversed lines); ``minslot`` (2F,) the
    smallest slot of each; ``edge_slots`` / ``vert_slots`` the faces' boundary lists as
    incidences (edge << 2 | upper << 1 | reversed; vertex << 3 | o << 2 | sign + 1).
    And the bookkeeping of the updates: ``blockers`` (4n²,) int32 one object blocking each
    candidate (−1 free; any blocker will do, so an updated complex's may differ from a
    rebuild's), ``lines`` (L, 2) the degenerate lines re-scanned by earlier updates (θ, u),
    ``open_rel`` (1,) the gap of the opened scene (0: no contacts)."""
    st = cx.state
    if st is None or cx.blockers is None:
        return None
    m, F = cx.n_vertices, cx.n_faces
    rep = st["face_label"]
    tw = st["c_twin"][rep]
    lab = np.full(st["c_tail"].shape[0], -1, np.int64)
    lab[tw] = 2 * np.arange(F) + 1
    lab[rep] = 2 * np.arange(F)  # a face that is its own twin keeps 2·f
    minslot = np.full(2 * F, -1, np.int64)
    minslot[lab[tw]] = st["c_minslot"][tw]
    minslot[lab[rep]] = st["c_minslot"][rep]
    lines = st.get("lines", (np.zeros(0), np.zeros(0)))
    return dict(incidence=st["s_occ"] + st["s_role"] * 2 * m, tail=st["tail"], head=st["head"], th0=st["th0"],
                th1=st["th1"], integral=st["I"], arclength=st["arc"], slot_face=lab[st["comp"]], minslot=minslot,
                edge_slots=st["fe_packed"], vert_slots=st["fv_packed"], blockers=cx.blockers.astype(np.int32),
                lines=np.stack(lines, 1).reshape(-1, 2), open_rel=np.array([st.get("open", (0.0,))[0]], np.float64))


def check_update_arrays(c, arrays, upd, n):
    """Refuse an ``update`` group that does not fit the complex (shapes, ids in range, the
    incidences a permutation in curve order): ``c`` a :class:`viscx.formats.validate.Checker`.
    Returns the arrays (numbers checked by kind)."""
    m = arrays["v_key"].shape[0]
    F = arrays["f_area"].shape[0]
    N = 4 * m
    where = "/update/"
    need = dict(incidence=(N, "i"), tail=(N, "i"), head=(N, "i"), th0=(N, "f"), th1=(N, "f"), integral=(N, "f"),
                arclength=(N, "f"), slot_face=(3 * N, "i"), minslot=(2 * F, "i"),
                edge_slots=(arrays["f_edge"].shape[0], "i"), vert_slots=(arrays["f_vert"].shape[0], "i"),
                blockers=(4 * n * n, "i"))
    out = {}
    for name, (size, kind) in need.items():
        if name not in upd:
            c.fail(where + name, "missing")
        a = c.convert(where + name, upd[name], kind)
        if a.shape != (size,):
            c.fail(where + name, f"shape {a.shape}, expected ({size},)")
        out[name] = a
    lines = c.convert(where + "lines", upd.get("lines", np.zeros((0, 2))), "f")
    if lines.ndim != 2 or lines.shape[1] != 2:
        c.fail(where + "lines", f"shape {lines.shape}, expected (L, 2)")
    out["lines"] = lines
    rel = c.convert(where + "open_rel", upd.get("open_rel", np.zeros(1)), "f")
    if rel.shape != (1,) or float(rel[0]) not in (0.0,) + C.OPEN_RELS:
        c.fail(where + "open_rel", "not [0] or [one of the opening gaps]")
    out["open_rel"] = float(rel[0])
    inc = out["incidence"]
    c.within(where + "incidence", inc, 0, N)
    if N and np.bincount(inc, minlength=N).max() != 1:
        c.fail(where + "incidence", "not a permutation of the incidences")
    for name in ("tail", "head", "blockers"):
        c.within(where + name, out[name], -1, n)
    c.within(where + "slot_face", out["slot_face"], 0, 2 * F)
    c.within(where + "minslot", out["minslot"], -1, 3 * N)
    c.within(where + "edge_slots", out["edge_slots"] >> 2, 0, N)
    c.within(where + "vert_slots", out["vert_slots"] >> 3, 0, m)
    # the order along the curves: (curve, θ, τ, occurrence) strictly increasing
    st = _incidence_state(arrays, inc)
    key = (st["s_cur"], st.get("s_ths", st["s_th"]), st["s_tau"], st["s_occ"])
    less, same = np.zeros(N - 1, bool), np.ones(N - 1, bool)
    for k_ in key:
        less |= same & (k_[1:] > k_[:-1])
        same &= k_[1:] == k_[:-1]
    if N > 1 and not less.all():
        c.fail(where + "incidence", "not in order along the tangency curves")
    return out


def _incidence_state(V, inc):
    """The sorted incidence arrays of the state from the incidence order ``inc``."""
    m = V["v_key"].shape[0]
    O = C.occurrences(V)
    occ, role = inc % (2 * m), inc // (2 * m)
    st = dict(s_occ=occ, s_role=role, s_cur=np.where(role == 0, 2 * O["K1"][occ] + O["S1"][occ],
                                                         2 * O["K2"][occ] + O["S2"][occ]),
              s_th=O["TH"][occ], s_tau=O["TAU"][occ])
    if "v_theta_sort" in V:
        st["s_ths"] = O["THS"][occ]
    return st


def state_from_update_arrays(cx: C.FlatComplex, upd: dict) -> C.FlatComplex:
    """The complex with the state and blocker table of its file's ``update`` group
    (:func:`update_arrays`, checked by :func:`check_update_arrays`): O(m) gathers instead
    of the derivation; the opened scene of touching objects made again."""
    V = cx.arrays
    F = cx.n_faces
    st = _incidence_state(V, upd["incidence"])
    C.link(st, 2 * V["v_key"].shape[0])
    st.update(tail=upd["tail"], head=upd["head"], th0=upd["th0"], th1=upd["th1"], I=upd["integral"],
              arc=upd["arclength"], comp=upd["slot_face"], c_minslot=upd["minslot"])
    has = np.zeros(2 * F, bool)
    has[st["comp"]] = True
    f = np.arange(F)
    pair = V["f_pair"]
    st["c_tail"] = np.full(2 * F, -3, np.int64)
    st["c_head"] = np.full(2 * F, -3, np.int64)
    st["c_tail"][0::2], st["c_head"][0::2] = pair[:, 0], pair[:, 1]
    st["c_tail"][1::2] = np.where(has[1::2], pair[:, 1], -3)
    st["c_head"][1::2] = np.where(has[1::2], pair[:, 0], -3)
    st["c_twin"] = np.stack([np.where(has[1::2], 2 * f + 1, 2 * f), 2 * f], 1).reshape(-1)
    for name, own, twin in (("c_area", "f_area", "f_area_twin"), ("c_strings", "f_strings", "f_strings_twin"),
                            ("c_bounded", "f_bounded", "f_bounded"), ("c_hash", "f_hash", "f_hash_twin")):
        st[name] = np.stack([V[own], V[twin]], 1).reshape(-1)
    st["face_label"] = 2 * f
    st["fe_start"], st["fe_packed"] = V["f_edge_start"], upd["edge_slots"]
    st["fv_start"], st["fv_packed"] = V["f_vert_start"], upd["vert_slots"]
    st["lines"] = (upd["lines"][:, 0].copy(), upd["lines"][:, 1].copy())
    if upd["open_rel"]:
        opened = cx.scene.opened(upd["open_rel"])
        opened._contacts = np.zeros((0, 2), np.int64)
        st["open"] = (upd["open_rel"], opened)
    return C.FlatComplex(scene=cx.scene, eps=cx.eps, arrays=cx.arrays, state=st,
                         blockers=upd["blockers"].astype(np.int32))
