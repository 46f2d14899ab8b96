"""The render job: primary hits, exact direct illumination (or its sparse reconstruction,
or a Monte Carlo reference), tone mapping and region overlays."""

import time
from dataclasses import dataclass, field

import numpy as np

from viscx.errors import ParameterError
from viscx.render.camera import primary_hits
from viscx.render.direct import DirectLighting, Lighting, emitter, regions_of
from viscx.render.sparse import LUMINANCE
from viscx.render.tiles import shade_tiles

#: The tone map's white: this percentile of the luminance of the lit, non-emitting pixels.
WHITE_PERCENTILE = 99.0
#: Colour of region boundaries drawn by ``--show-regions`` (8-bit RGB).
REGION_COLOUR = np.array([255, 220, 0], np.uint8)


def auto_exposure(radiance, face, light_faces):
    """The exposure that maps the ``WHITE_PERCENTILE`` luminance of the pixels that see
    a non-emitting face to 1 (1 when there is none or it is black)."""
    seen = (face >= 0) & ~np.isin(face, light_faces)
    lum = radiance[seen] @ LUMINANCE
    white = float(np.percentile(lum, WHITE_PERCENTILE)) if len(lum) else 0.0
    return 1.0 / white if white > 0 else 1.0


def tonemap(radiance, exposure):
    """Linear radiance to 8-bit sRGB: scale by ``exposure``, clip to [0, 1], sRGB curve.

    radiance : (h, w, 3) float. Returns (h, w, 3) uint8.
    """
    x = np.clip(np.asarray(radiance, dtype=np.float64) * exposure, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return (x * 255.0 + 0.5).astype(np.uint8)


def region_boundaries(label):
    """(h, w) bool: pixels whose label differs from the one to the right or below.

    label : (h, w) int.
    """
    edge = np.zeros(label.shape, bool)
    edge[:, :-1] |= label[:, :-1] != label[:, 1:]
    edge[:-1, :] |= label[:-1, :] != label[1:, :]
    return edge


@dataclass
class Render:
    """An image and what it cost.

    Attributes
    ----------
    radiance : (h, w, 3) float64
        Linear radiance.
    label : (h, w) int64
        Region of each pixel (-1 background), for overlays.
    hits : viscx.render.camera.Hits
    stats : dict
    stderr : (h, w, 3) float64 or None
        Standard error of a Monte Carlo image.
    light_faces : (k,) int64
        The light's faces (left out of the automatic exposure).
    """

    radiance: np.ndarray
    label: np.ndarray
    hits: object
    stats: dict = field(default_factory=dict)
    stderr: np.ndarray = None
    light_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def _labels(face, side, region):
    """One id per (face, side, region) in sorted order, -1 for the background."""
    out = np.full(len(face), -1, np.int64)
    hit = face >= 0
    if np.any(hit):
        _, inv = np.unique(np.stack([face[hit], side[hit], region[hit]], axis=1), axis=0, return_inverse=True)
        out[hit] = inv.reshape(-1)
    return out


def render(scene, mesh, camera, radiance=None, samples=None, reference=None, seed=0, progress=None, light=None):
    """Render the direct illumination of an area light (module docstring).

    The exact image is evaluated tile by tile (:func:`viscx.render.tiles.shade_tiles`: no
    discontinuity mesh needed); the mesh, when given, labels its pixels by their regions
    (``--show-regions``). The sparse reconstruction needs the mesh (it interpolates inside
    its regions); the Monte Carlo reference does not.

    Parameters
    ----------
    scene : Scene
    mesh : viscx.queries.discontinuities.DiscontinuityMesh or None
        The light's discontinuity mesh; None with ``light``.
    camera : viscx.render.camera.Camera
    radiance : (3,) float, optional
        The light's radiance (default: its material's Ke).
    samples : int, optional
        Sparse reconstruction from this many samples (plus the regions' corners).
    reference : int, optional
        Monte Carlo with this many light samples per pixel instead (no mesh needed).
    seed : int
    progress : callable, optional
        Called with pixels done (Monte Carlo only).
    light : viscx.scene.light.Light, optional
        The light when no mesh is given.

    Returns
    -------
    Render
    """
    if mesh is None and samples is not None:
        raise ParameterError("{samples} interpolates inside the regions of the light's discontinuity mesh: give the mesh")
    light = mesh.light if mesh is not None else light
    t0 = time.perf_counter()
    em = emitter(scene, light, radiance)
    lighting = Lighting(scene, em) if mesh is None else DirectLighting(scene, mesh, em)
    hits = primary_hits(scene, camera)
    t1 = time.perf_counter()
    stats = {"pixels": int(len(hits.face)), "pixels_hit": int(np.sum(hits.face >= 0)), "primary_s": round(t1 - t0, 4)}
    stderr = None
    no_region = np.full(len(hits.face), -1, np.int64)
    if reference is not None:
        from viscx.render.montecarlo import reference_radiance

        rad, err = reference_radiance(lighting, hits.face, hits.side, hits.point, int(reference), seed, progress)
        label = _labels(hits.face, hits.side, no_region)
        stderr = err.reshape(*hits.shape, 3)
        stats.update(method="monte carlo", light_samples=int(reference), rays=int(reference) * stats["pixels_hit"],
                     noise=float(np.sqrt(np.mean(err[hits.face >= 0] ** 2))) if stats["pixels_hit"] else 0.0)
    elif samples is not None:
        from viscx.render.sparse import reconstruct

        rec = reconstruct(lighting, hits, int(samples))
        rad, label = rec.radiance, rec.label
        stats.update(method="sparse", samples=int(len(rec.samples)), corners=int(len(rec.corners)),
                     evaluations=int(rec.evaluations), regions=int(label.max() + 1))
    else:
        rad, tiles = shade_tiles(Lighting(scene, em), hits)
        region = no_region if mesh is None else regions_of(lighting, hits.face, hits.point)
        label = _labels(hits.face, hits.side, region)
        stats.update(method="exact", regions=int(label.max() + 1), **tiles)
    stats["shading_s"] = round(time.perf_counter() - t1, 4)
    stats["seconds"] = round(time.perf_counter() - t0, 4)
    return Render(rad.reshape(*hits.shape, 3), label.reshape(hits.shape), hits, stats, stderr,
                  np.asarray(light.faces, np.int64))


def picture(result, light_faces, exposure=None, show_regions=False):
    """The 8-bit picture of a render: tone mapped, region boundaries drawn on request.

    Returns
    -------
    rgb : (h, w, 3) uint8
    exposure : float
    """
    face = result.hits.face
    if exposure is None:
        exposure = auto_exposure(result.radiance.reshape(-1, 3), face, light_faces)
    rgb = tonemap(result.radiance, exposure)
    if show_regions:
        rgb[region_boundaries(result.label)] = REGION_COLOUR
    return rgb, float(exposure)
