"""The form-factor matrix file (``viscx formfactor matrix FILE -o F.h5``).

Layout (HDF5, written atomically)::

    /                 attrs: format="viscx-formfactors", format_version, viscx_version,
                             scene_sha256, scene_name, tol, summary (JSON)
    /formfactors      CSR over elements: element 2 f is the front of face f (its
                      normal side), 2 f + 1 its back
        indptr  (2n + 1,) int64     indices (nnz,) int64
        data    (nnz,) float64      F[(i, s), (j, t)]
        error   (nnz,) float64      its error estimate
        sky     (2n,) float64       F to the sky (what leaves the scene)
        sky_error (2n,) float64
        area    (n,) float64        face areas (A_i F_ij = A_j F_ji)
        row_sum (2n,) float64       Σ_j F + sky (1 up to the errors)

Plain exports (by the output's suffix, :func:`write_export`): ``.npz`` holds the same
arrays plus ``groups`` (names) and ``group_F`` (g, g + 1), the area-weighted form factor
from the front sides of each group's faces to (both sides of) each group's faces, last
column the sky; ``.csv`` is that group table, one line per pair of groups with F > 0.
"""

import json
from pathlib import Path

import h5py
import numpy as np

from viscx import __version__
from viscx.errors import ViscxError
from viscx.formats.atomic import atomic_path
from viscx.formats.hdf5 import write_dataset

FORMAT = "viscx-formfactors"
FORMAT_VERSION = 1
_ARRAYS = ["indptr", "indices", "data", "error", "sky", "sky_error", "area"]


def write_matrix(path, matrix, scene):
    """Write a :class:`viscx.queries.formfactor.Matrix` atomically; returns its summary."""
    summary = matrix.summary()
    with atomic_path(path, stream=False) as tmp:
        with h5py.File(tmp, "w", track_order=True) as f:
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["viscx_version"] = __version__
            f.attrs["scene_sha256"] = scene.sha256
            f.attrs["scene_name"] = Path(scene.source).name if scene.source else ""
            f.attrs["tol"] = matrix.tol
            f.attrs["summary"] = json.dumps(summary, sort_keys=True)
            g = f.create_group("formfactors", track_order=True)
            for name in _ARRAYS:
                write_dataset(g, name, getattr(matrix, name))
            write_dataset(g, "row_sum", matrix.row_sums())
    return summary


def read_matrix(path):
    """The arrays of a matrix file as a dict (plus ``summary``)."""
    try:
        f = h5py.File(path, "r")
    except OSError:
        raise ViscxError(f"{path} is not a readable HDF5 file") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise ViscxError(f"{path} is not a viscx form-factor file")
        out = {name: f["formfactors"][name][()] for name in [*_ARRAYS, "row_sum"]}
        out["summary"] = json.loads(f.attrs["summary"])
    return out


def group_matrix(matrix, scene):
    """(g, g + 1) float64: F from the front sides of group a's faces (area-weighted) to both
    sides of group b's faces; the last column is the sky."""
    n = scene.n_faces
    g = len(scene.group_names)
    rows = np.repeat(np.arange(2 * n), np.diff(matrix.indptr))
    front = rows % 2 == 0
    face_i, face_j = rows[front] // 2, matrix.indices[front] // 2
    weight = matrix.area[face_i] * matrix.data[front]
    out = np.zeros((g, g + 1))
    np.add.at(out, (scene.face_group[face_i], scene.face_group[face_j]), weight)
    np.add.at(out[:, g], scene.face_group, matrix.area * matrix.sky[0::2])
    area = np.bincount(scene.face_group, weights=matrix.area, minlength=g)
    return out / np.where(area > 0, area, 1.0)[:, None]


def write_export(path, matrix, scene):
    """Write the matrix as ``.npz`` or the group table as ``.csv`` (module docstring);
    returns its summary."""
    summary = matrix.summary()
    names = list(scene.group_names)
    table = group_matrix(matrix, scene)
    suffix = Path(path).suffix.lower()
    with atomic_path(path) as tmp:
        if suffix == ".npz":
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **{name: getattr(matrix, name) for name in _ARRAYS}, row_sum=matrix.row_sums(),
                                    groups=np.asarray(names), group_F=table, summary=json.dumps(summary, sort_keys=True))
        else:
            with open(tmp, "w") as f:
                f.write("from_group,to_group,F\n")
                for a in range(len(names)):
                    for b in range(len(names) + 1):
                        if table[a, b] > 0:
                            f.write(f"{names[a]},{names[b] if b < len(names) else 'sky'},{table[a, b]:.10g}\n")
    return summary
