"""``viscx flatland``: the 2-D visibility complex of convex objects and radiosity (Orti et al.)."""

import json
import time
from pathlib import Path

import click

from viscx.cli.options import output_option, quiet
from viscx.errors import ViscxError

SCENE_SUFFIXES = (".json", ".svg", ".dxf")


def _load_complex(path, q, with_mesh=False):
    """A complex from a flatland HDF5/msgpack file, or built from a scene file."""
    from viscx.flatland.complex import build
    from viscx.flatland.scene import load_scene
    from viscx.formats.flatland import read_any

    p = Path(path)
    if not p.is_file():
        raise ViscxError(f"no such file: {path}")
    if p.suffix.lower() in SCENE_SUFFIXES:
        cx = build(load_scene(p), quiet=q)
        return (cx, None) if with_mesh else cx
    return read_any(p, with_mesh=with_mesh)


def _object_index(scene, spec):
    if spec in scene.names:
        return scene.names.index(spec)
    try:
        k = int(spec)
    except ValueError:
        raise ViscxError(f"--object {spec!r}: no object of that name or index") from None
    if not 0 <= k < scene.n:
        raise ViscxError(f"--object {k}: the scene has objects 0..{scene.n - 1}")
    return k


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def flatland():
    """The 2-D visibility complex of disjoint convex objects, form factors and radiosity.

    \b
    viscx flatland build sample_scenes/flatland/three_circles.json -o three.h5
    viscx flatland formfactor three.h5
    viscx flatland radiosity three.h5 -o three_rad.h5
    viscx flatland move three.h5 --object 2 --by 0.5,-0.25
    viscx flatland insert three.h5 --object '{"type": "circle", "center": [2, 3], "radius": 0.5}'
    viscx flatland remove three.h5 --object 1
    viscx flatland plot three_rad.h5 -o three.png
    """


@flatland.command()
@click.argument("scene_file", type=click.Path(dir_okay=False))
@output_option("The flatland HDF5 file to write (.h5), or msgpack (.msgpack).")
@click.option("--epsilon", type=float, default=None, metavar="EPS",
              help="Chord length below which a line only grazes an object. Default: 1e-9 of the scene diagonal.")
@click.option("--perturb", type=float, default=None, metavar="REL",
              help="Rotate and shift every object by ~REL x the scene diagonal first, e.g. 1e-7. Not needed "
                   "for degenerate layouts (aligned rows, grids: built exactly); kept to test sensitivity.")
@click.pass_context
def build(ctx, scene_file, output, epsilon, perturb):
    """Build the visibility complex of a JSON, SVG or DXF flatland scene.

    \b
    viscx flatland build sample_scenes/flatland/three_circles.json -o three.h5
    viscx flatland build sample_scenes/flatland/room.svg -o room.msgpack
    viscx flatland build plan.dxf -o plan.h5
    """
    from viscx.flatland.complex import build as build_complex
    from viscx.flatland.scene import load_scene
    from viscx.formats.flatland import write_any

    if epsilon is not None and not epsilon > 0:
        raise ViscxError("--epsilon must be > 0")
    q = quiet(ctx)
    scene = load_scene(scene_file)
    if perturb is not None:
        if not 0 < perturb < 1e-2:
            raise ViscxError("--perturb must be in (0, 0.01)")
        scene = scene.perturbed(perturb)
    t0 = time.perf_counter()
    cx = build_complex(scene, eps=epsilon, quiet=q)
    dt = time.perf_counter() - t0
    write_any(output, cx)
    click.echo(f"{scene.n} objects: {cx.n_vertices} vertices, {cx.n_edges} edges, {cx.n_faces} faces "
               f"({dt:.3f} s) -> {output}")


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--method", type=click.Choice(["area", "strings", "both"]), default="both", show_default=True,
              help="Dual face areas (a), signed vertex/edge sums (b), or both with their difference.")
@output_option("Write the matrix as JSON here instead of printing it.", required=False)
@click.pass_context
def formfactor(ctx, file, method, output):
    """Print the object-to-object form factors F_ij (last column: the blue sky).

    \b
    viscx flatland formfactor three.h5
    viscx flatland formfactor sample_scenes/flatland/three_circles.json --method area -o F.json
    """
    import numpy as np

    from viscx.formats.atomic import atomic_path

    cx = _load_complex(file, quiet(ctx))
    F = cx.F_area if method != "strings" else cx.F_strings
    names = list(cx.scene.names) + ["sky"]
    if output:
        doc = {"objects": names[:-1], "columns": names, "method": method, "F": F.tolist()}
        if method == "both":
            doc["F_strings"] = cx.F_strings.tolist()
        with atomic_path(output) as tmp:
            Path(tmp).write_text(json.dumps(doc, indent=1))
        click.echo(f"form factors of {cx.scene.n} objects -> {output}")
        return
    w = max(8, max(len(x) for x in names))
    click.echo(" " * w + " ".join(f"{x[:w]:>{w}}" for x in names))
    for i in range(cx.scene.n):
        click.echo(f"{names[i][:w]:<{w}}" + " ".join(f"{v:>{w}.6f}" for v in F[i]))
    if method == "both":
        click.echo(f"max |F_area - F_strings| = {np.max(np.abs(cx.F_area - cx.F_strings)):.3e}")


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@output_option("The flatland HDF5 (.h5) or msgpack file to write, with the mesh and radiosity.")
@click.option("--sky-radiance", type=float, default=0.0, show_default=True, metavar="L",
              help="Radiosity of a uniform sky (an emitter at infinity): gives each element its diffuse "
                   "irradiance, per side for segments.")
@click.pass_context
def radiosity(ctx, file, output, sky_radiance):
    """Discontinuity mesh from the complex's vertices, element form factors, B = E + ρFB.

    \b
    viscx flatland radiosity three.h5 -o three_rad.h5
    viscx flatland radiosity sample_scenes/flatland/three_circles.json -o three_rad.h5
    viscx flatland radiosity rows.json --sky-radiance 1 -o rows_rad.h5
    """
    import numpy as np

    from viscx.flatland.mesh import radiosity as solve
    from viscx.flatland.scene import SEGMENT
    from viscx.formats.flatland import write_any

    q = quiet(ctx)
    cx = _load_complex(file, q)
    mesh = solve(cx, quiet=q, sky_radiance=sky_radiance)
    write_any(output, cx, mesh)
    k, B, H, Le = mesh["elem_obj"], mesh["elem_B"], mesh["elem_H"], mesh["elem_length"]
    click.echo(f"{len(B)} elements, {int(mesh['iterations'])} Gauss-Seidel sweeps -> {output}")

    def mean(x, m):
        return np.sum(x[m] * Le[m]) / np.sum(Le[m])

    for i in range(cx.scene.n):
        m = k == i
        line = (f"  {cx.scene.names[i]}: mean B = {mean(B, m):.6g} (min {B[m].min():.6g}, max {B[m].max():.6g}), "
                f"mean irradiance {mean(H, m):.6g}")
        if cx.scene.kind[i] == SEGMENT:
            side = mesh["elem_edge"]
            line += f" (right side {mean(H, m & (side == 0)):.6g}, left side {mean(H, m & (side == 1)):.6g})"
        click.echo(line)


def _update_file(file, output, change):
    """The flow of move / insert / remove: read the complex, ``change(cx)`` -> (new complex,
    MoveStats, what was done), write it atomically (FILE in place by default), print the
    zone.  The mesh of a radiosity file is not carried over (re-run ``radiosity``)."""
    from viscx.formats.atomic import release_input
    from viscx.formats.flatland import read_any, write_any

    if not Path(file).is_file():
        raise ViscxError(f"no such file: {file}")
    cx = read_any(file)
    if output is None:  # the documented update in place
        release_input(file)
    t0 = time.perf_counter()
    new, stats, what = change(cx)
    dt = time.perf_counter() - t0
    write_any(output or file, new)
    click.echo(f"{what} in {dt:.3f} s -> {output or file}")
    click.echo(stats.summary())


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--object", "obj", required=True, metavar="K", help="The object to move: its index or name.")
@click.option("--by", "by", required=True, metavar="DX,DY", help="The translation, e.g. 0.5,-1.")
@output_option("Where to write the updated complex (default: update FILE in place).", required=False)
@click.pass_context
def move(ctx, file, obj, by, output):
    """Move one object and update the complex and only the form factors whose faces changed.

    \b
    viscx flatland move three.h5 --object 2 --by 0.5,-0.25
    viscx flatland move three.h5 --object lamp --by 1,0 -o three_moved.h5
    """
    from viscx.flatland.dynamic import move as move_object

    try:
        dx, dy = (float(x) for x in by.split(","))
    except ValueError:
        raise ViscxError(f"--by {by!r}: expected DX,DY (two numbers separated by a comma)") from None

    def change(cx):
        k = _object_index(cx.scene, obj)
        return (*move_object(cx, k, dx, dy), f"moved {cx.scene.names[k]!r} by ({dx:g}, {dy:g})")

    _update_file(file, output, change)


def _objects_of(spec):
    """Object dicts from ``--object``: inline JSON (one object, a list, or a scene
    document ``{"objects": [...]}``) or a scene file (.json/.svg/.dxf: all its objects)."""
    from viscx.flatland.scene import load_scene

    text = spec.strip()
    if text[:1] in "{[":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise ViscxError(f"--object: not valid JSON ({e.msg} at character {e.pos})") from None
        doc = doc.get("objects", doc) if isinstance(doc, dict) else doc
        return [doc] if isinstance(doc, dict) else doc
    if Path(spec).suffix.lower() in SCENE_SUFFIXES:
        return load_scene(spec).to_json()["objects"]
    raise ViscxError(f"--object {spec!r}: expected a JSON object or a scene file (.json, .svg, .dxf)")


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--object", "spec", required=True, metavar="SPEC",
              help="The object(s) to insert: JSON as in a scene file (one object, a list, or {\"objects\": ...}) "
                   "or a .json/.svg/.dxf scene file whose objects are all inserted.")
@output_option("Where to write the updated complex (default: update FILE in place).", required=False)
@click.pass_context
def insert(ctx, file, spec, output):
    """Insert objects after the scene's and update the complex in their zone only.

    \b
    viscx flatland insert three.h5 --object '{"type": "circle", "center": [2, 3], "radius": 0.5, "name": "pot"}'
    viscx flatland insert three.h5 --object shed.svg -o three_shed.h5
    """
    from viscx.flatland.dynamic import insert as insert_objects

    objects = _objects_of(spec)

    def change(cx):
        new, stats = insert_objects(cx, objects)
        names = new.scene.names[cx.scene.n:]
        return new, stats, f"inserted {', '.join(map(repr, names))}"

    _update_file(file, output, change)


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--object", "obj", required=True, metavar="K", help="The object to remove: its index or name.")
@output_option("Where to write the updated complex (default: update FILE in place).", required=False)
@click.pass_context
def remove(ctx, file, obj, output):
    """Remove one object (the later ones move down an index) and update the complex in its zone only.

    \b
    viscx flatland remove three.h5 --object 1
    viscx flatland remove three.h5 --object lamp -o three_dark.h5
    """
    from viscx.flatland.dynamic import remove as remove_object

    def change(cx):
        k = _object_index(cx.scene, obj)
        return (*remove_object(cx, k), f"removed {cx.scene.names[k]!r}")

    _update_file(file, output, change)


@flatland.command()
@click.argument("file", type=click.Path(dir_okay=False))
@output_option("The image to write (.png, .svg or .pdf).")
@click.option("--what", type=click.Choice(["all", "scene", "dual", "matrix"]), default="all", show_default=True,
              help="The scene with per-element radiosity, the dual arrangement, the form-factor matrix, or all.")
@click.pass_context
def plot(ctx, file, output, what):
    """Pictures like Orti et al. Fig. 9 (needs matplotlib: pip install 'viscx[plot]').

    \b
    viscx flatland plot three_rad.h5 -o three.png
    viscx flatland plot three.h5 --what dual -o dual.svg
    """
    from viscx.flatland.plot import plot as draw

    cx, mesh = _load_complex(file, quiet(ctx), with_mesh=True)
    draw(cx, mesh, output, what=what)
    click.echo(f"{what} -> {output}")
