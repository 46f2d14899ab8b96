"""Image files: 8-bit PNG (tone-mapped, for looking at) and linear float images (PFM and
``.npy``, for comparing with any renderer). Every file is written atomically."""

import struct
import zlib

import numpy as np

from viscx.formats.atomic import atomic_path


def write_png(path, rgb):
    """Write an 8-bit RGB PNG (no dependency: zlib and the PNG chunk layout).

    Parameters
    ----------
    rgb : (h, w, 3) uint8
        Row 0 is the top of the image.
    """
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, _ = rgb.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rgb.reshape(h, 3 * w)], axis=1)  # filter 0 per row

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    body = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + chunk(b"IEND", b""))
    with atomic_path(path) as tmp:
        tmp.write_bytes(body)


def read_png(path):
    """Read a PNG written by :func:`write_png` (8-bit RGB, filter 0): (h, w, 3) uint8."""
    data = open(path, "rb").read()
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    return rows[:, 1:].reshape(h, w, 3)


def write_pfm(path, rgb):
    """Write a little-endian colour PFM (linear float32; the format stores the bottom row first).

    Parameters
    ----------
    rgb : (h, w, 3) float
        Row 0 is the top of the image.
    """
    rgb = np.asarray(rgb, dtype="<f4")
    h, w, _ = rgb.shape
    with atomic_path(path) as tmp:
        tmp.write_bytes(f"PF\n{w} {h}\n-1.0\n".encode() + np.ascontiguousarray(rgb[::-1]).tobytes())


def read_pfm(path):
    """Read a colour PFM: (h, w, 3) float32, row 0 the top."""
    data = open(path, "rb").read()
    head = data.split(b"\n", 3)
    w, h = map(int, head[1].split())
    scale = float(head[2])
    arr = np.frombuffer(head[3], dtype="<f4" if scale < 0 else ">f4").reshape(h, w, 3)
    return arr[::-1].astype(np.float32)


def write_npy(path, array):
    """``numpy.save`` through a temporary file."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, np.asarray(array))
