"""The form-factor matrix file (``viscx formfactor --matrix -o F.h5``).

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
