"""A vertex's V-cells on its direction sphere: two equal-area hemispheres, one colour per cell.

Each hemisphere (+y seen from above, -y seen from below: the samples' y is up) is a
Lambert azimuthal equal-area disk, so areas on the page are proportional to solid
angles. Every pixel's direction is located among the vertex's cells
(:func:`viscx.skeleton.vcells.locate`); pixels where no cell, or several, hold the
direction are black (they show loops V1 could not close).
"""

from pathlib import Path

import numpy as np

from viscx.errors import ViscxError
from viscx.formats.atomic import atomic_path
from viscx.plot import pyplot
from viscx.skeleton.nodes import BLOCK_SKY, BLOCK_VERTEX
from viscx.skeleton.vcells import locate

#: (centre, screen right, screen up) of the two views, each right-handed with the centre
#: towards the viewer (seen from outside the sphere).
VIEWS = (
    ("+y, seen from above", np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])),
    ("-y, seen from below", np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])),
)


# pixel centres span the disk of radius √2 (a hemisphere under the equal-area map)
_HALF = np.sqrt(2)
EXTENT = (-_HALF, _HALF, -_HALF, _HALF)


def hemisphere_directions(centre, right, up, size):
    """Directions of the pixels of a Lambert azimuthal equal-area disk of a hemisphere.

    Parameters
    ----------
    centre, right, up : (3,) float
    size : int
        Pixels per side.

    Returns
    -------
    directions : (size, size, 3) float
        Unit directions (row 0 at the top); NaN outside the disk.
    """
    x = np.linspace(-np.sqrt(2), np.sqrt(2), size)
    X, Y = np.meshgrid(x, -x)
    rho2 = X**2 + Y**2
    w = 1 - rho2 / 2
    k = np.sqrt(np.clip(1 - rho2 / 4, 0, None))
    d = w[..., None] * centre + k[..., None] * (X[..., None] * right + Y[..., None] * up)
    d[rho2 > 2] = np.nan
    return d


def blocker_name(kind, index, scene):
    """'sky', 'v<id>' or the face's group name and id."""
    if kind == BLOCK_SKY:
        return "sky"
    if kind == BLOCK_VERTEX:
        return f"v{index}"
    return f"{scene.group_names[scene.face_group[index]]}#{index}"


def plot_vcells(scene, arcs, vcells, vertex, output, size=300):
    """Draw the V-cells of ``vertex`` into ``output`` (.png, .svg or .pdf).

    Parameters
    ----------
    scene : Scene
    arcs : Arcs
    vcells : VCells
    vertex : int
    output : str or Path
    size : int
        Pixels per hemisphere side.

    Returns
    -------
    dict
        ``{"cells": number of cells, "unlocated": fraction of pixels in no cell or several}``.
    """
    suffix = Path(output).suffix.lower().lstrip(".")
    if suffix not in ("png", "svg", "pdf"):
        raise ViscxError(f"{output}: the image must be .png, .svg or .pdf")
    cells = np.flatnonzero(vcells.vertex == vertex)
    if len(cells) == 0:
        raise ViscxError(f"vertex {vertex} has no V-cells (is it a generator vertex?)")
    plt = pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    palette = plt.get_cmap("tab20").colors
    colours = np.array([palette[i % len(palette)] for i in range(len(cells))] + [(0.0, 0.0, 0.0)])
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4), gridspec_kw={"width_ratios": [1, 1, 0.9]})
    missed = total = 0
    for ax, (title, centre, right, up) in zip(axes, VIEWS):
        d = hemisphere_directions(centre, right, up, size)
        disk = ~np.isnan(d[..., 0])
        cell, _ = locate(scene, arcs, vcells, vertex, d[disk])
        index = np.full(d.shape[:2], -1)
        index[disk] = np.where(cell >= 0, np.searchsorted(cells, cell), len(cells))
        missed += np.count_nonzero(cell < 0)
        total += len(cell)
        image = np.ma.masked_less(index, 0)
        ax.imshow(image, cmap=ListedColormap(colours), vmin=-0.5, vmax=len(cells) + 0.5, interpolation="nearest",
                  extent=EXTENT)
        # cell boundaries: pixels whose neighbour holds another cell
        edge = np.zeros(index.shape, bool)
        edge[:, 1:] |= (index[:, 1:] != index[:, :-1]) & (index[:, :-1] >= 0) & (index[:, 1:] >= 0)
        edge[1:, :] |= (index[1:, :] != index[:-1, :]) & (index[:-1, :] >= 0) & (index[1:, :] >= 0)
        ax.imshow(np.ma.masked_where(~edge, edge), cmap=ListedColormap([(0.2, 0.2, 0.2)]), interpolation="nearest",
                  extent=EXTENT)
        ax.add_patch(plt.Circle((0, 0), np.sqrt(2), fill=False, lw=0.8))
        names = ("x", "y", "z")
        axis = lambda v: ("+" if v.sum() > 0 else "-") + names[int(np.argmax(np.abs(v)))]  # noqa: E731
        ax.text(1.5, 0, axis(right), va="center", fontsize=8)
        ax.text(0, 1.5, axis(up), ha="center", fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.set_xlim(-1.7, 1.7)
        ax.set_ylim(-1.7, 1.7)
        ax.set_aspect("equal")
        ax.axis("off")
    handles = [
        Patch(color=colours[i], label=f"{c}: {blocker_name(vcells.up_kind[c], vcells.up[c], scene)} → "
                                      f"{blocker_name(vcells.down_kind[c], vcells.down[c], scene)}  "
                                      f"{vcells.solid_angle[c]:.4f} sr" + ("  (holes)" if vcells.loop_offsets[c + 1] - vcells.loop_offsets[c] > 1 else ""))
        for i, c in enumerate(cells[:40])
    ]
    if missed:
        handles.append(Patch(color="black", label=f"in no cell or several ({missed / total:.1%})"))
    axes[2].legend(handles=handles, loc="upper left", fontsize=7, frameon=False, title="cell: up → down, solid angle")
    axes[2].axis("off")
    x = scene.vertices[vertex]
    fig.suptitle(f"V-cells of vertex {vertex} at ({x[0]:.4g}, {x[1]:.4g}, {x[2]:.4g}): {len(cells)} cells "
                 f"(equal-area hemispheres)", fontsize=11)
    fig.tight_layout()
    with atomic_path(output) as tmp:
        fig.savefig(tmp, format=suffix, dpi=110)
    plt.close(fig)
    return {"cells": len(cells), "unlocated": missed / max(total, 1)}
