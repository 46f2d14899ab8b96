"""Pictures of a flatland complex (Orti et al. Fig. 9): the scene with per-element radiosity,
the dual arrangement of the tangency curves with the complex's vertices, and the
form-factor matrix.  matplotlib is imported lazily (the ``plot`` extra)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.formats.atomic import atomic_path


def _mpl():
    from viscx.render import pyplot

    plt = pyplot()
    from matplotlib.collections import LineCollection

    return plt, LineCollection


def draw_scene(ax, cx, mesh=None):
    """Objects, free bitangents (thin) and, with a mesh, each element coloured by its B."""
    plt, LineCollection = _mpl()
    sc = cx.scene
    if cx.n_vertices:
        segs = np.stack([cx.v_p, cx.v_q], axis=1)
        ax.add_collection(LineCollection(segs, colors="0.8", linewidths=0.4, zorder=1))
    for k in range(sc.n):
        poly = sc.object_polygon(k)
        ax.fill(poly[:, 0], poly[:, 1], color="#ffd966" if sc.emission[k] > 0 else "0.92", zorder=2)
        ax.annotate(sc.names[k], poly.mean(axis=0), ha="center", va="center", fontsize=7, zorder=4)
    if mesh is not None and "elem_B" in mesh:
        from viscx.flatland.mesh import point_at

        lines, vals = [], []
        for e, (k, (s0, s1)) in enumerate(zip(mesh["elem_obj"], mesh["elem_s"])):
            pts = point_at(sc, int(k), np.linspace(s0, s1, 12))
            lines += [pts[i:i + 2] for i in range(len(pts) - 1)]
            vals += [mesh["elem_B"][e]] * (len(pts) - 1)
        lc = LineCollection(np.array(lines), array=np.array(vals), cmap="inferno", linewidths=3, zorder=3)
        ax.add_collection(lc)
        plt.colorbar(lc, ax=ax, label="radiosity B", shrink=0.8)
    else:
        for k in range(sc.n):
            poly = sc.object_polygon(k)
            ax.plot(*np.vstack([poly, poly[:1]]).T, color="k", lw=1, zorder=3)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_title("scene" + (" and radiosity per element" if mesh is not None else ""))


def draw_dual(ax, cx, samples=720):
    """Tangency curves λ_k (dashed) and μ_k over θ ∈ [0, π) and the vertices (dots)."""
    sc = cx.scene
    th = np.linspace(0, math.pi, samples)
    nrm = np.stack([-np.sin(th), np.cos(th)], axis=1)
    colors = [f"C{k % 10}" for k in range(sc.n)]
    for k in range(sc.n):
        v = sc.verts[sc.vert_start[k]:sc.vert_start[k + 1]]
        proj = nrm @ v.T
        r = sc.radius[k]
        ax.plot(th, proj.max(axis=1) + r, color=colors[k], lw=1, label=sc.names[k])
        ax.plot(th, proj.min(axis=1) - r, color=colors[k], lw=1, ls="--")
    if cx.n_vertices:
        u = np.einsum("ij,ij->i", np.stack([-np.sin(cx.v_theta), np.cos(cx.v_theta)], 1), cx.v_p)
        ax.plot(cx.v_theta, u, "k.", ms=3, label="vertices")
    ax.set_xlabel("θ")
    ax.set_ylabel("u")
    ax.set_title("dual arrangement (μ solid, λ dashed)")
    if sc.n <= 12:
        ax.legend(fontsize=6, loc="upper right")


def draw_matrix(ax, cx):
    plt, _ = _mpl()
    F = cx.F_area
    im = ax.imshow(F, cmap="viridis", vmin=0, vmax=max(F[:, :-1].max(), 1e-12))
    names = list(cx.scene.names) + ["sky"]
    if cx.scene.n <= 20:
        ax.set_xticks(range(len(names)), names, rotation=90, fontsize=6)
        ax.set_yticks(range(cx.scene.n), names[:-1], fontsize=6)
    plt.colorbar(im, ax=ax, shrink=0.8)
    ax.set_title("form factors F_ij (last column: sky)")


def plot(cx, mesh, output, what="all"):
    """Write the pictures to ``output`` (format from its suffix)."""
    plt, _ = _mpl()
    suffix = Path(output).suffix.lower().lstrip(".")
    if suffix not in ("png", "svg", "pdf"):
        raise ViscxError(f"{output}: the image must be .png, .svg or .pdf")
    panels = ["scene", "dual", "matrix"] if what == "all" else [what]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.5 * len(panels), 5))
    axes = np.atleast_1d(axes)
    for ax, p in zip(axes, panels):
        if p == "scene":
            draw_scene(ax, cx, mesh)
        elif p == "dual":
            draw_dual(ax, cx)
        else:
            draw_matrix(ax, cx)
    fig.tight_layout()
    with atomic_path(output) as tmp:
        fig.savefig(tmp, format=suffix, dpi=120)
    plt.close(fig)
