"""Dynamic update of the complex after an object moves (Orti et al. §4.3).

A translation of object K can only change

- the bitangents of K itself (all pairs (K, j)), and
- the freeness, tail or head of a bitangent of another pair whose *line* meets K before
  or after the move (K may start or stop blocking its segment, or become / stop being the
  first object at one of its ends).

So we recompute the candidates' closed-form lines (cheap, deterministic: bit-identical for
pairs that did not move), re-run the free-segment test only for the affected candidates
(lines meeting the bounding disk of K at either position, plus K's own pairs), keep every
other vertex as it was, and re-derive edges and faces.  A face whose boundary signature
(objects, sides, tails, heads and exact θ ranges of its edges) is unchanged keeps its area
and string sum; only the changed faces are re-summed, and only the form factors of object
pairs having a changed face are recomputed.  The result equals a rebuild from scratch
(tested on random moves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viscx.errors import ViscxError
from viscx.flatland import complex as C
from viscx.flatland.scene import check_disjoint


@dataclass
class MoveStats:
    """What a move recomputed, out of how many."""

    candidates_tested: int
    candidates_total: int
    faces_recomputed: int
    faces_total: int
    formfactors_recomputed: int
    formfactors_total: int

    def summary(self) -> str:
        return (f"form factors recomputed: {self.formfactors_recomputed} of {self.formfactors_total} "
                f"(object pairs incl. the sky); faces re-summed: {self.faces_recomputed} of {self.faces_total}; "
                f"bitangent candidates re-tested: {self.candidates_tested} of {self.candidates_total}")


def _bounding_disk(scene, k):
    v = scene.verts[scene.vert_start[k]:scene.vert_start[k + 1]]
    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return c, float(np.max(np.hypot(*(v - c).T)) + scene.radius[k])


def move(cx: C.FlatComplex, k: int, dx: float, dy: float):
    """Move object k by (dx, dy) and update the complex.

    Returns (new FlatComplex, MoveStats).  Raises ViscxError if k is not an object or the
    moved object would overlap another."""
    scene = cx.scene
    if not (0 <= k < scene.n):
        raise ViscxError(f"--object {k}: the scene has objects 0..{scene.n - 1}")
    if not (np.isfinite(dx) and np.isfinite(dy)):
        raise ViscxError("the displacement must be finite")
    new_scene = scene.moved(k, dx, dy)
    check_disjoint(new_scene)
    eps = cx.eps
    cand = C.candidates(new_scene)
    # affected: K's own pairs, and lines meeting K's bounding disk before or after
    theta = cand["theta"]
    nrm = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    # a point of each candidate line: its tangent point on object a
    sig = 2.0 * cand["side_a"] - 1.0
    pa = new_scene.verts[cand["va"]] + (sig * new_scene.radius[cand["a"]])[:, None] * nrm
    u = np.einsum("ij,ij->i", nrm, pa)
    todo = (cand["a"] == k) | (cand["b"] == k)
    for sc in (scene, new_scene):
        c, r = _bounding_disk(sc, k)
        todo |= np.abs(nrm @ c - u) <= r + 10 * eps
    cls = C.classify(new_scene, cand, eps, todo=todo)
    fresh = C.resolve_degenerate(new_scene, C.vertices_from(new_scene, cand, cls))
    # unaffected candidates keep their old status: the old vertices whose keys are not redone
    old_keys = cx.v_key
    redo_keys = cand["key"][todo]
    keep_old = ~np.isin(old_keys, redo_keys)
    if "v_tau" not in cx.arrays:  # a file written before degenerate lines were resolved
        cx.arrays["v_tau"] = np.zeros(cx.n_vertices)
    V = {}
    for name in ("v_key", "v_obj", "v_support", "v_side", "v_tail", "v_head", "v_theta", "v_tau", "v_p", "v_q", "v_length", "v_seg"):
        V[name] = np.concatenate([cx.arrays[name][keep_old], fresh[name]])
    order = np.argsort(V["v_key"], kind="stable")
    V = {name: arr[order] for name, arr in V.items()}
    # sky ends are clipped to the scene box, which the move may have changed
    V["v_seg"] = C.clip_sky_ends(new_scene, V["v_theta"], V["v_p"], V["v_q"], V["v_tail"], V["v_head"], V["v_seg"])
    previous = {name: cx.arrays[name] for name in ("f_hash", "f_hash_twin", "f_area", "f_area_twin",
                                                    "f_strings", "f_strings_twin")}
    out, recomputed = C.derive(new_scene, V, previous=previous)
    V.update(out)
    new = C.FlatComplex(scene=new_scene, eps=eps, arrays=V)
    stats = _stats(new, recomputed, int(todo.sum()), int(todo.size))
    return new, stats


def _pair_ids(f_pair, n):
    a = np.where(f_pair[:, 0] < 0, n, f_pair[:, 0])
    b = np.where(f_pair[:, 1] < 0, n, f_pair[:, 1])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return lo * (n + 1) + hi


def _stats(new, recomputed, tested, total):
    n = new.scene.n
    ok = new.f_bounded & ~((new.f_pair[:, 0] < 0) & (new.f_pair[:, 1] < 0))
    pid = _pair_ids(new.f_pair, n)[ok]
    pairs_all = np.unique(pid)
    pairs_re = np.unique(pid[recomputed[ok]])
    return MoveStats(candidates_tested=tested, candidates_total=total,
                     faces_recomputed=int(recomputed[ok].sum()), faces_total=int(ok.sum()),
                     formfactors_recomputed=int(pairs_re.size), formfactors_total=int(pairs_all.size))
