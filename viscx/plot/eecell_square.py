"""An edge pair's EE-cells in its square [0, 1]² (Hoberock et al. Fig. 7): one colour per cell.

Pixel (x1, x2) is the line through e1(x1) and e2(x2) (x1 to the right, x2 up). Every
pixel is located among the pair's cells (:func:`viscx.skeleton.eecells.locate`); pixels
in no cell are light grey (no free segment joins the two points there, or a loop V1
could not close), pixels in several black. The boundary elements are drawn over them
with an arrow in their direction of travel (their cell on their left).
"""

from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.formats.atomic import atomic_path
from viscx.plot import pyplot
from viscx.skeleton.eecells import cell_elements, locate
from viscx.skeleton.nodes import BLOCK_EDGE, BLOCK_SKY

#: Points drawn along each boundary element.
CURVE_POINTS = 64


def blocker_name(kind, index, scene):
    """'sky', 'edge <id>' or the face's group name and id."""
    if kind == BLOCK_SKY:
        return "sky"
    if kind == BLOCK_EDGE:
        return f"edge {index}"
    return f"{scene.group_names[scene.face_group[index]]}#{index}"


def element_points(el, n=CURVE_POINTS):
    """(k, n, 2) points along each element (its rational Bézier coordinates)."""
    u = np.linspace(0.0, 1.0, n)[None, :, None]
    w = el.weight[:, None, :]
    a, b = (1 - u) * (1 - w), u * w
    return (a * el.start[:, None, :2] + b * el.end[:, None, :2]) / (a + b)


def plot_eecells(scene, arcs, eecells, e1, e2, output, size=300):
    """Draw the EE-cells of the edge pair (e1 < e2) into ``output`` (.png, .svg or .pdf).

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    eecells : EECells
    e1, e2 : int
    output : str or Path
    size : int
        Pixels per side of the square.

    Returns
    -------
    dict
        ``{"cells": number of cells, "hidden": fraction of pixels in no cell, "conflict":
        fraction in several}``.
    """
    suffix = Path(output).suffix.lower().lstrip(".")
    if suffix not in ("png", "svg", "pdf"):
        raise ViscxError(f"{output}: the image must be .png, .svg or .pdf")
    cells = np.flatnonzero((eecells.edge1 == e1) & (eecells.edge2 == e2))
    plt = pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    palette = plt.get_cmap("tab20").colors
    colours = [palette[i % len(palette)] for i in range(len(cells))] + [(0.88, 0.88, 0.88), (0.0, 0.0, 0.0)]
    x = (np.arange(size) + 0.5) / size
    X1, X2 = np.meshgrid(x, x[::-1])  # row 0 at the top: x2 = 1
    cell, holders = locate(scene, arcs, eecells, e1, e2, np.stack([X1.ravel(), X2.ravel()], axis=1))
    index = np.where(cell >= 0, np.searchsorted(cells, cell), np.where(holders == 0, len(cells), len(cells) + 1))
    fig, (ax, legend) = plt.subplots(1, 2, figsize=(11, 5.6), gridspec_kw={"width_ratios": [1, 0.8]})
    ax.imshow(index.reshape(size, size), cmap=ListedColormap(colours), vmin=-0.5, vmax=len(cells) + 1.5,
              interpolation="nearest", extent=(0, 1, 0, 1))
    if len(cells):
        el, _, _ = cell_elements(scene, arcs, eecells, cells)
        for line in element_points(el):
            ax.plot(line[:, 0], line[:, 1], color=(0.15, 0.15, 0.15), lw=0.9)
            mid = len(line) // 2
            ax.annotate("", xy=line[mid + 1], xytext=line[mid - 1],
                        arrowprops={"arrowstyle": "->", "color": (0.15, 0.15, 0.15), "lw": 0.9})
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.set_aspect("equal")
    ax.set_xlabel(f"x1 along edge {e1}")
    ax.set_ylabel(f"x2 along edge {e2}")
    handles = [
        Patch(color=colours[i], label=f"{c}: {blocker_name(eecells.back_kind[c], eecells.back[c], scene)} → "
                                      f"{blocker_name(eecells.front_kind[c], eecells.front[c], scene)}  "
                                      f"area {eecells.area[c]:.4f}"
                                      + ("  (holes)" if eecells.loop_offsets[c + 1] - eecells.loop_offsets[c] > 1 else ""))
        for i, c in enumerate(cells[:40])
    ]
    hidden, conflict = np.mean(holders == 0), np.mean(holders > 1)
    if hidden:
        handles.append(Patch(color=colours[-2], label=f"no cell: hidden or not closed ({hidden:.1%})"))
    if conflict:
        handles.append(Patch(color="black", label=f"in several cells ({conflict:.1%})"))
    legend.legend(handles=handles, loc="upper left", fontsize=7, frameon=False, title="cell: back → front, area")
    legend.axis("off")
    fig.suptitle(f"EE-cells of edges {e1} and {e2}: {len(cells)} cells (line through e{e1}(x1) and e{e2}(x2))",
                 fontsize=11)
    fig.tight_layout()
    with atomic_path(output) as tmp:
        fig.savefig(tmp, format=suffix, dpi=110)
    plt.close(fig)
    return {"cells": len(cells), "hidden": float(hidden), "conflict": float(conflict)}
