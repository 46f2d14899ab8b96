"""Exact direct illumination from an area light, evaluated region by region of the
light's discontinuity mesh (Hoberock et al. §7.4–7.5).

Radiance
--------
A Lambertian receiver point x (reflectance ρ, normal n on the side that is seen) lit by
light faces of radiance Le (uniform, emitted from each light face's front, the side its
normal points to) reflects

    L(x) = ρ/π · E(x),   E(x) = Σ_l Le_l ∫_{V_l(x)} cos θ_x cos θ_y / r² dA = π Σ_l Le_l F_l(x),

so L(x) = ρ · Σ_l Le_l F_l(x), where V_l(x) is the part of light face l that x sees and
F_l(x) the form factor from a differential area at x to V_l(x): Lambert's contour sum over
the exact polygon V_l(x) (:func:`viscx.geometry.occlusion.visible_form_factors`, central
projection of the occluders onto the light's plane and polygon clipping in float64).
Nothing is sampled.

Using the structure
-------------------
Which occluders can hide part of the light from x depends only on where x is; the
discontinuity mesh of the light (:mod:`viscx.queries.discontinuities`, traced from V1)
cuts every receiver into regions in which the visible part of the light keeps its
combinatorial structure. Per region R and light face l, the occluders that matter are
the faces meeting the interior of the convex hull of R ∪ l (every segment from a point of
R to the light lies in it): for all the regions of a receiver at once (one exact
separating-axis pass in numba, :func:`viscx.geometry.occlusion.shaft_meets`, over the
receiver's own shaft occluders whose boxes meet the region's shaft), and every pixel of R is evaluated in one batch with only those. A fully lit
region has none (Lambert's formula on the whole light); an umbra or penumbra region has
the few that bound its shadow. This is exact whatever the mesh: a region's shaft contains
every segment from its points to the light, so culling never drops a real occluder; a
missed event only makes a region's list longer. Points that fall in no region (on the
mesh lines within rounding) use the receiver's whole list.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from viscx.errors import ParameterError, ViscxError, literal
from viscx.geometry.occlusion import shaft_meets
from viscx.queries.formfactor import PairSetup, convex_outline, face_target

#: Reflectance of faces without a material (Kd).
DEFAULT_KD = 0.75


@dataclass
class Emitter:
    """An area light with its radiance.

    Attributes
    ----------
    light : viscx.scene.light.Light
    radiance : (k, 3) float64
        Emitted radiance (RGB) of each light face, from its front side.
    """

    light: object
    radiance: np.ndarray


def emitter(scene, light, radiance=None):
    """The light's radiance: ``radiance`` (R, G, B) for every face, else each face's
    material emission (Ke); ViscxError when that is zero everywhere."""
    faces = light.faces
    if radiance is not None:
        le = np.tile(np.asarray(radiance, dtype=np.float64).reshape(1, 3), (len(faces), 1))
    else:
        mat = scene.face_material[faces]
        le = np.zeros((len(faces), 3))
        ok = mat >= 0
        if len(scene.material_ke):
            le[ok] = scene.material_ke[mat[ok]]
    if not np.all(np.isfinite(le)) or np.any(le < 0):
        raise ViscxError("the light's radiance must be finite and non-negative")
    if not np.any(le > 0):
        raise ParameterError(f"light {literal(light.name)} emits nothing (no Ke in its material); give {{radiance}} R,G,B")
    return Emitter(light, le)


def reflectance(scene):
    """(f, 3) float64: each face's diffuse reflectance (Kd; DEFAULT_KD without a material)."""
    kd = np.full((scene.n_faces, 3), DEFAULT_KD)
    mat = scene.face_material
    ok = mat >= 0
    if len(scene.material_kd):
        kd[ok] = scene.material_kd[mat[ok]]
    return kd


@njit(cache=True)
def _locate(points, edge_a, edge_b, edge_loop, loop_region, loop_hole, n_regions):
    """Region of each 2-D point: inside the region's outer loop and none of its holes
    (even-odd crossings of a ray towards +x), -1 when in none."""
    n_loops = loop_region.shape[0]
    out = np.full(points.shape[0], -1, np.int64)
    parity = np.zeros(n_loops, np.bool_)
    state = np.zeros(n_regions, np.int64)  # 1 in the outer loop, 2 in a hole too
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        parity[:] = False
        for e in range(edge_a.shape[0]):
            ay, by = edge_a[e, 1], edge_b[e, 1]
            if (ay > py) != (by > py):
                x = edge_a[e, 0] + (py - ay) * (edge_b[e, 0] - edge_a[e, 0]) / (by - ay)
                if x > px:
                    parity[edge_loop[e]] = not parity[edge_loop[e]]
        state[:] = 0
        for L in range(n_loops):
            if parity[L]:
                r = loop_region[L]
                state[r] = max(state[r], 2 if loop_hole[L] else 1)
        for r in range(n_regions):
            if state[r] == 1:
                out[i] = r
                break
    return out


class Locator:
    """Point location in one receiver's regions (its discontinuity-mesh subdivision)."""

    def __init__(self, receiver):
        self.receiver = receiver
        a, b, lo, lr, lh = [], [], [], [], []
        for r, g in enumerate(receiver.regions):
            for hole, loop in [(False, g.outer)] + [(True, h) for h in g.holes]:
                loop = np.asarray(loop, dtype=np.float64)
                a.append(loop)
                b.append(np.roll(loop, -1, axis=0))
                lo.append(np.full(len(loop), len(lr), np.int64))
                lr.append(r)
                lh.append(hole)
        self.edge_a = np.ascontiguousarray(np.concatenate(a)) if a else np.zeros((0, 2))
        self.edge_b = np.ascontiguousarray(np.concatenate(b)) if b else np.zeros((0, 2))
        self.edge_loop = np.concatenate(lo) if lo else np.zeros(0, np.int64)
        self.loop_region = np.asarray(lr, np.int64)
        self.loop_hole = np.asarray(lh, np.bool_)

    def to2(self, points):
        u, v, _ = self.receiver.frame
        return np.ascontiguousarray(np.stack([points @ u, points @ v], axis=1))

    def __call__(self, points):
        """(m,) int64: the region of each point (m, 3) of the face, -1 in none."""
        if len(self.loop_region) == 0:
            return np.full(len(points), -1, np.int64)
        return _locate(self.to2(points), self.edge_a, self.edge_b, self.edge_loop, self.loop_region, self.loop_hole,
                       len(self.receiver.regions))


class Lighting:
    """A scene lit by an emitter: the faces' reflectances and the light's emission (what
    the Monte Carlo reference needs, :mod:`viscx.render.montecarlo`).

    Parameters
    ----------
    scene : Scene
    emitter : Emitter
    """

    def __init__(self, scene, emitter):
        self.scene = scene
        self.emitter = emitter
        self.kd = reflectance(scene)
        self._setups = {}

    def _pairs(self, face, side):
        """Per light face: its PairSetup with this receiver side, or None (cannot see it)."""
        key = (int(face), int(side))
        if key not in self._setups:
            out = []
            for l in self.emitter.light.faces:
                if l == face:
                    out.append(None)
                    continue
                s = PairSetup(self.scene, int(face), int(side), face_target(self.scene, int(l)), 1)
                out.append(None if s.empty else s)
            self._setups[key] = out
        return self._setups[key]

    def _reflected(self, face, side, points, kernel):
        """Reflected radiance (m, 3) at points (m, 3) of one face seen from one side, light
        face k's form factors with the occluders of ``kernel(k, setup)``
        (:meth:`viscx.queries.formfactor.PairSetup.kernel_for`)."""
        total = np.zeros((len(points), 3))
        for k, setup in enumerate(self._pairs(face, side)):
            if setup is None:
                continue
            # points behind the light's plane (or on it) do not see its front
            front = points @ setup.n_t - setup.c_t > setup.tiny
            if not np.any(front):
                continue
            f = np.zeros(len(points))
            f[front] = setup.f(points[front], kernel(k, setup))
            total += np.maximum(f, 0.0)[:, None] * self.emitter.radiance[k][None, :]
        return total * self.kd[face][None, :]

    def whole_radiance(self, face, side, points):
        """Exact reflected radiance (m, 3) at points (m, 3) of one face seen from one side,
        past every occluder of each (receiver, light face) pair (the faces meeting the
        shaft of the whole receiver and light face): nothing culled per point, the
        reference the culled evaluations are checked against."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        return self._reflected(face, side, points, lambda k, setup: setup.kernel)

    def emitted(self, face, side):
        """(3,) float64: radiance a light face emits towards the seen side (zero elsewhere)."""
        where = np.flatnonzero(self.emitter.light.faces == face)
        if side > 0 and len(where):
            return self.emitter.radiance[where[0]]
        return np.zeros(3)


class DirectLighting(Lighting):
    """Exact direct radiance of receiver points, region by region (module docstring).

    Parameters
    ----------
    scene : Scene
    mesh : viscx.queries.discontinuities.DiscontinuityMesh
        The light's discontinuity mesh (its regions locate the points).
    emitter : Emitter
    """

    def __init__(self, scene, mesh, emitter):
        super().__init__(scene, emitter)
        self.mesh = mesh
        self.is_light = np.zeros(scene.n_faces, bool)
        self.is_light[emitter.light.faces] = True
        self.receivers = {r.face: r for r in mesh.receivers}
        self._locators = {}
        self._kernels = {}
        self._culled = {}
        self._wanted = {}
        self.stats = {"regions": 0, "points": 0, "unlocated": 0, "occluders": 0}

    # -- where a point is --------------------------------------------------------------
    def locate(self, face, points):
        """(m,) int64: region of each point (m, 3) on ``face`` (-1 in none, or a light face)."""
        rec = self.receivers.get(int(face))
        if rec is None:
            return np.full(len(points), -1, np.int64)
        if face not in self._locators:
            self._locators[face] = Locator(rec)
        return self._locators[face](np.asarray(points, dtype=np.float64))

    def region_loops(self, face, region):
        """The region's loops in 3-D (outer first)."""
        rec = self.receivers[int(face)]
        g = rec.regions[region]
        return [rec.to3(g.outer)] + [rec.to3(h) for h in g.holes]

    # -- what is needed for one (face, side) -------------------------------------------
    def want(self, face, regions):
        """Announce the regions of ``face`` whose points will be evaluated: their occluders
        are culled together (one numba call), the others never. A receiver has thousands
        of regions and an image sees a part of them (the bunny's floor at 128²: 2,258 of
        11,722); without it, every region of the face is culled at its first use."""
        self._wanted.setdefault(int(face), set()).update(int(r) for r in np.asarray(regions).ravel() if r >= 0)

    def _region_occluders(self, face, side, k, setup, region):
        """The pair's occluders meeting the interior of the region's shaft to light face k
        (the convex hull of the region and J', so of their convex outlines): (c,) int64
        into ``setup.occluders``, ascending. Culled for every wanted region of the
        receiver not culled yet at once (:meth:`want`; every region when none was
        announced): one numba call (:func:`viscx.geometry.occlusion.shaft_meets`) over the
        (region, occluder) pairs whose boxes meet; a region's answer does not depend on
        which others are culled with it."""
        face = int(face)
        done = self._culled.setdefault((face, int(side), k), {})
        if region not in done:
            rec = self.receivers[face]
            todo = self._wanted[face] if face in self._wanted else range(len(rec.regions))
            todo = np.array(sorted(set(todo) - done.keys() | {int(region)}), np.int64)
            hulls = [convex_outline([rec.to3(rec.regions[r].outer)], setup.n_i) for r in todo]
            kc = max(len(h) for h in hulls)
            # (padded by repeating the last vertex: a zero edge gives no axis)
            cells = np.stack([np.concatenate([h, np.repeat(h[-1:], kc - len(h), axis=0)]) for h in hulls])
            target = convex_outline(setup.J, setup.n_t)
            pts, lo, hi, normals = setup.occluder_outlines
            tol = setup.tiny
            o_lo, o_hi = np.minimum.reduceat(pts, lo, axis=0), np.maximum.reduceat(pts, lo, axis=0)
            s_lo = np.minimum(cells.min(axis=1), target.min(axis=0)) - tol
            s_hi = np.maximum(cells.max(axis=1), target.max(axis=0)) + tol
            cell, ids = [], []
            for c0 in range(0, len(cells), 256):  # box test in blocks of regions
                near = (o_lo[None] <= s_hi[c0 : c0 + 256, None]).all(axis=2) & (o_hi[None] >= s_lo[c0 : c0 + 256, None]).all(axis=2)
                r, o = np.nonzero(near)
                cell.append(r + c0)
                ids.append(o)
            cell, ids = np.concatenate(cell).astype(np.int64), np.concatenate(ids).astype(np.int64)
            meets = shaft_meets(cells, np.ascontiguousarray(np.broadcast_to(setup.n_i, (len(cells), 3))), target,
                                np.asarray(setup.n_t, np.float64), cell, ids, pts, lo, hi, normals, tol)
            ptr = np.r_[0, np.cumsum(np.bincount(cell[meets], minlength=len(cells)))].astype(np.int64)
            ids = ids[meets]
            for i, r in enumerate(todo):
                done[int(r)] = ids[ptr[i]:ptr[i + 1]]
        return done[region]

    def _kernel(self, face, side, region, k, setup):
        """The kernel of light face k for points of one region (-1: all the pair's occluders)."""
        key = (int(face), int(side), int(region), k)
        if key not in self._kernels:
            occ = setup.occluders
            if region >= 0 and occ:
                occ = [occ[i] for i in self._region_occluders(face, side, k, setup, int(region))]
            self.stats["occluders"] += len(occ)
            self._kernels[key] = setup.kernel_for(occ)
        return self._kernels[key]

    def radiance(self, face, side, region, points):
        """Exact reflected radiance (RGB) at points of one face seen from one side.

        Parameters
        ----------
        face, side : int
        region : int
            The region all the points lie in (:meth:`locate`), -1 when unknown.
        points : (m, 3) float64

        Returns
        -------
        (m, 3) float64
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros((0, 3))
        self.stats["points"] += len(points)
        self.stats["regions"] += 1
        if region < 0:
            self.stats["unlocated"] += len(points)
        return self._reflected(face, side, points, lambda k, setup: self._kernel(face, side, region, k, setup))


def regions_of(lighting, face, points):
    """(n,) int64: the region of the light's discontinuity mesh each point is in (-1 for
    the background, light faces, and points on the mesh lines within rounding).

    face : (n,) int64; points : (n, 3) float64.
    """
    region = np.full(len(face), -1, np.int64)
    hit = np.flatnonzero(face >= 0)
    for f in np.unique(face[hit]):
        on = hit[face[hit] == f]
        region[on] = lighting.locate(f, points[on])
    return region


def groups_of(*keys):
    """Rows with equal keys, in sorted key order: ``(keys (g, k), members)``, members a
    list of (m_i,) int64 row indices (increasing).

    keys : (n,) int each (small: faces, sides, regions).
    """
    key = np.stack(keys, axis=1).astype(np.int64)
    # one sortable code per row (the columns' ranges are small): a 1-D sort, not a row sort
    lo = key.min(axis=0) if len(key) else np.zeros(key.shape[1], np.int64)
    span = (key.max(axis=0) - lo + 1) if len(key) else np.ones(key.shape[1], np.int64)
    code = np.zeros(len(key), np.int64)
    for c in range(key.shape[1]):
        code = code * span[c] + (key[:, c] - lo[c])
    order = np.argsort(code, kind="stable")
    first = np.flatnonzero(np.r_[True, code[order][1:] != code[order][:-1]]) if len(code) else np.zeros(0, np.int64)
    bounds = np.r_[first, len(code)]
    return key[order[first]], [order[bounds[g]:bounds[g + 1]] for g in range(len(first))]


def shade(lighting, face, side, points):
    """Exact radiance (direct light reflected, plus emission) of shading points, evaluated
    in one batch per (face, side, region).

    Parameters
    ----------
    lighting : DirectLighting
    face, side : (n,) int64
        Face seen and side (-1 background).
    points : (n, 3) float64

    Returns
    -------
    radiance : (n, 3) float64
    region : (n,) int64
        :func:`regions_of`.
    """
    out = np.zeros((len(face), 3))
    region = regions_of(lighting, face, points)
    hit = np.flatnonzero(face >= 0)
    groups, members = groups_of(face[hit], side[hit], region[hit])
    for f in np.unique(groups[:, 0]):  # only the regions seen are culled
        lighting.want(f, groups[groups[:, 0] == f, 2])
    for (f, s, r), rows in zip(groups, members):
        idx = hit[rows]
        out[idx] = lighting.radiance(f, s, r, points[idx]) + lighting.emitted(f, s)[None, :]
    return out, region
