"""Side by side with Mitsuba 3 on the Cornell box's direct illumination (reports, never asserts).

Mitsuba's ``direct`` integrator (``scalar_rgb`` variant) estimates the same image as
``viscx render`` (Lambertian Kd, the light's Ke from its front, direct light only) by
sampling the light: its error falls as 1/√spp. The viscx image is exact. Compared on the
pixels whose 3 × 3 neighbourhood sees one face (Mitsuba averages over each pixel, viscx
shades its centre: across a silhouette they differ by design; inside a face the pixel's
average and centre differ only by the illumination's curvature).

Run with a Python that has mitsuba (a side environment, never a viscx dependency) and the
``viscx`` command on PATH (or in $VISCX):

    python -m venv /tmp/peers && /tmp/peers/bin/pip install mitsuba
    /tmp/peers/bin/python benchmarks/mitsuba_cornell.py [--size 256] [--spp 4 16 64 256 1024]
"""

import argparse
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OBJ = ROOT / "sample_scenes" / "cornell_box.obj"
EYE, AT, UP, FOV = (278, 273, -800), (278, 273, 0), (0, 1, 0), 39.3


def read_objects(path):
    """{object name: (material, vertices (k, 3), faces as vertex index lists)} of a simple OBJ."""
    materials = {}
    for line in (path.with_suffix(".mtl")).read_text().splitlines():
        p = line.split()
        if p and p[0] == "newmtl":
            name = p[1]
            materials[name] = {}
        elif p and p[0] in ("Kd", "Ke"):
            materials[name][p[0]] = [float(x) for x in p[1:4]]
    verts, objects, current = [], {}, None
    for line in path.read_text().splitlines():
        p = line.split()
        if not p:
            continue
        if p[0] == "o":
            current = objects.setdefault(p[1], {"material": None, "faces": []})
        elif p[0] == "usemtl":
            current["material"] = p[1]
        elif p[0] == "v":
            verts.append([float(x) for x in p[1:4]])
        elif p[0] == "f":
            current["faces"].append([int(x.split("/")[0]) - 1 for x in p[1:]])
    return np.array(verts), objects, materials


def write_ply(path, vertices, faces):
    """A triangulated ASCII PLY of some faces (fans), for Mitsuba's ply loader."""
    used = sorted({v for f in faces for v in f})
    index = {v: i for i, v in enumerate(used)}
    tris = [(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)]
    lines = ["ply", "format ascii 1.0", f"element vertex {len(used)}", "property float x", "property float y",
             "property float z", f"element face {len(tris)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(f"{x:.6f}" for x in vertices[v]) for v in used]
    lines += [f"3 {index[a]} {index[b]} {index[c]}" for a, b, c in tris]
    path.write_text("\n".join(lines) + "\n")


def mitsuba_scene(tmp, size):
    import mitsuba as mi

    vertices, objects, materials = read_objects(OBJ)
    scene = {"type": "scene",
             "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
             "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "y",
                        "to_world": mi.ScalarTransform4f().look_at(origin=EYE, target=AT, up=UP),
                        "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                                 "pixel_format": "rgb"},
                        "sampler": {"type": "independent", "sample_count": 1}}}
    for name, obj in objects.items():
        ply = Path(tmp) / f"{name}.ply"
        write_ply(ply, vertices, obj["faces"])
        mat = materials[obj["material"]]
        shape = {"type": "ply", "filename": str(ply), "face_normals": True,
                 "bsdf": {"type": "twosided", "material": {"type": "diffuse",
                                                          "reflectance": {"type": "rgb", "value": mat["Kd"]}}}}
        if "Ke" in mat:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": mat["Ke"]}}
        scene[name] = shape
    return mi.load_dict(scene)


def viscx_exact(tmp, size):
    viscx = os.environ.get("VISCX", "viscx")
    h5 = Path(tmp) / "cornell.h5"
    subprocess.run([viscx, "-q", "build", str(OBJ), "-o", str(h5)], check=True)
    png = Path(tmp) / "exact.png"
    cmd = [viscx, "-q", "render", str(h5), "--camera", ",".join(map(str, EYE)), "--look-at", ",".join(map(str, AT)),
           "--fov", str(FOV), "--size", str(size), str(size), "--light-group", "light", "-o", str(png)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    return np.load(png.with_suffix(".npy")).astype(np.float64), time.perf_counter() - t0


def main():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64, 256, 1024])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        exact, exact_s = viscx_exact(tmp, args.size)
        scene = mitsuba_scene(tmp, args.size)
        mi.render(scene, spp=1)  # warm up
        lum = exact @ np.array([0.2126, 0.7152, 0.0722])
        # pixels inside one face: the exact image is smooth in their 3 x 3 neighbourhood
        inner = np.zeros(lum.shape, bool)
        c = lum[1:-1, 1:-1]
        steps = [np.abs(lum[1 + dy:lum.shape[0] - 1 + dy, 1 + dx:lum.shape[1] - 1 + dx] - c)
                 for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        inner[1:-1, 1:-1] = (np.max(steps, axis=0) <= 0.05 * np.percentile(lum, 99)) & (c < 5.0)
        scale = float(np.sqrt(np.mean(exact[inner] ** 2)))
        flip = None
        print(f"viscx exact, {args.size}x{args.size}: {exact_s:.2f} s (whole command); {inner.sum()} pixels compared")
        print("| Mitsuba spp | seconds | RMSE vs exact (of its RMS) |")
        print("|---:|---:|---:|")
        for spp in args.spp:
            t0 = time.perf_counter()
            img = np.array(mi.render(scene, spp=spp), dtype=np.float64)[:, :, :3]
            dt = time.perf_counter() - t0
            if flip is None:  # the screen's x axis: take the orientation that matches
                flip = np.mean((img[:, ::-1][inner] - exact[inner]) ** 2) < np.mean((img[inner] - exact[inner]) ** 2)
            if flip:
                img = img[:, ::-1]
            rmse = float(np.sqrt(np.mean((img[inner] - exact[inner]) ** 2)))
            print(f"| {spp} | {dt:.2f} | {rmse:.3g} ({rmse / scale:.2%}) |")


if __name__ == "__main__":
    main()
