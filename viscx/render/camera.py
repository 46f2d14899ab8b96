"""A pinhole camera and the primary hits of its pixels (the shading points of an image)."""

from dataclasses import dataclass

import numpy as np

from viscx.errors import ParameterError, literal
from viscx.tolerances import ANGLE_TOLERANCE


@dataclass
class Camera:
    """A pinhole camera: one ray per pixel centre.

    Attributes
    ----------
    eye, look_at, up : (3,) float64
    fov : float
        Vertical field of view in degrees.
    width, height : int
        Pixels; row 0 is the top of the image.
    """

    eye: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov: float
    width: int
    height: int

    def __post_init__(self):
        self.eye = np.asarray(self.eye, dtype=np.float64).reshape(3)
        self.look_at = np.asarray(self.look_at, dtype=np.float64).reshape(3)
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)
        if not 0.0 < self.fov < 180.0:
            raise ParameterError(f"{{fov}} {literal(self.fov)} must be between 0 and 180 degrees")
        if self.width < 1 or self.height < 1:
            raise ParameterError(f"{{size}} {self.width} {self.height} must be at least 1 pixel each way")
        forward = self.look_at - self.eye
        if np.linalg.norm(forward) == 0.0:
            raise ParameterError("{eye} and {look_at} are the same point")
        if np.linalg.norm(np.cross(forward, self.up)) <= ANGLE_TOLERANCE * np.linalg.norm(forward) * np.linalg.norm(self.up):
            raise ParameterError("{up} must not be parallel to the viewing direction")

    def frame(self):
        """``(right, true_up, forward)``: a right-handed orthonormal frame with the camera
        looking along ``forward`` (image x grows to the right, y upwards)."""
        f = self.look_at - self.eye
        f /= np.linalg.norm(f)
        r = np.cross(f, self.up)
        r /= np.linalg.norm(r)
        return r, np.cross(r, f), f

    def rays(self):
        """Unit directions through the pixel centres, row by row from the top.

        Returns
        -------
        (height * width, 3) float64
        """
        r, u, f = self.frame()
        half = np.tan(np.radians(self.fov) / 2.0)
        aspect = self.width / self.height
        x = ((np.arange(self.width) + 0.5) / self.width * 2.0 - 1.0) * half * aspect
        y = (1.0 - (np.arange(self.height) + 0.5) / self.height * 2.0) * half
        d = f[None, None, :] + x[None, :, None] * r[None, None, :] + y[:, None, None] * u[None, None, :]
        d = d.reshape(-1, 3)
        return d / np.linalg.norm(d, axis=1)[:, None]


@dataclass
class Hits:
    """What every pixel sees first.

    Attributes
    ----------
    face : (n,) int64
        Face id, -1 for the background.
    point : (n, 3) float64
        The hit point (nan for the background).
    side : (n,) int64
        +1 when the camera sees the face's front (the side its normal points to), -1 the back.
    shape : tuple of int
        ``(height, width)``.
    """

    face: np.ndarray
    point: np.ndarray
    side: np.ndarray
    shape: tuple


def primary_hits(scene, camera):
    """Cast one ray per pixel (the scene's ray caster: embree, float64 where in doubt).

    Returns
    -------
    Hits
    """
    d = camera.rays()
    o = np.broadcast_to(camera.eye, d.shape)
    face, t = scene.ray_caster.first_hit(o, d)
    hit = face >= 0
    point = np.full(d.shape, np.nan)
    point[hit] = camera.eye + t[hit, None] * d[hit]
    side = np.zeros(len(face), np.int64)
    side[hit] = np.where(np.einsum("ij,ij->i", scene.face_normal[face[hit]], d[hit]) < 0.0, 1, -1)
    return Hits(face, point, side, (camera.height, camera.width))
