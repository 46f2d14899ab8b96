"""``viscx info``: what a viscx file holds."""

import json

import click


def file_summary(path):
    """Counts per level, options and timings of a viscx file, as a dict."""
    import numpy as np  # here, not at the top: `viscx --help` lists this command without numpy

    from viscx.formats.hdf5 import ViscxFile

    with ViscxFile(path) as f:
        scene = f.read_scene()
        attrs = f.h5.attrs
        groups = {
            name: int(np.count_nonzero(scene.face_group == i)) for i, name in enumerate(scene.group_names)
        }
        counts = {
            "scene": scene_counts(scene),
            **{level: level_counts(f.h5[level], float(attrs["epsilon"]))
               for level in f.levels if level != "scene" and level in f.h5},
        }
        return {
            "file": str(path),
            "format_version": int(attrs["format_version"]),
            "viscx_version": str(attrs["viscx_version"]),
            "scene": str(attrs["scene_name"]),
            "scene_sha256": str(attrs["scene_sha256"]),
            "epsilon": float(attrs["epsilon"]),
            "options": f.options,
            "levels": f.levels,
            "counts": counts,
            "groups": groups,
            "timings": f.timings,
        } | completeness(counts)


def completeness(counts):
    """The fraction of generator vertices whose V-cells are complete and of edge pairs whose
    EE-cells are, from the V2 counts: ``{"complete": {"vertices": [k, n, k / n], "ee_pairs":
    [...]}}``, or nothing without V2. Cells elsewhere may be wrong (docs/skeleton.md), so
    this is the share of the scene the queries answer exactly."""
    v2 = counts.get("V2")
    if not v2:
        return {}
    out = {}
    for name, done, total in (("vertices", "complete_vertices", "vertices"), ("ee_pairs", "ee_complete_pairs", "ee_pairs")):
        if total in v2 and done in v2:
            k, n = v2[done], v2[total]
            out[name] = [k, n, k / n if n else 1.0]
    return {"complete": out}


def scene_counts(scene):
    """Counts of the scene level."""
    import numpy as np
    return {
        "vertices": scene.n_vertices,
        "faces": scene.n_faces,
        "triangles": len(scene.triangles),
        "half_edges": len(scene.half_edges.start),
        "edges": len(scene.half_edges.edge_vertices),
        "generator_edges": len(scene.generator_edges),
        "generator_vertices": len(scene.generator_vertices),
        "holes": int(np.sum(np.diff(scene.face_loop_offsets) - 1)),
    }


def level_counts(group, epsilon):
    """Counts of a skeleton level: those it stores (attribute ``counts``), by kind where the
    level says its kinds, else rows per dataset; for V0 also its *sites*, the nodes merged
    within epsilon (:mod:`viscx.skeleton.sites`)."""
    import numpy as np
    if "counts" in group.attrs:
        return {name: int(value) for name, value in json.loads(group.attrs["counts"]).items()}
    if "kind" in group and "kinds" in group.attrs:
        kinds = json.loads(group.attrs["kinds"])
        kind = group["kind"][()]
        counts = {"total": int(len(kind)), **{name: int(np.count_nonzero(kind == k)) for name, k in kinds.items()}}
        if group.name == "/V0":
            from viscx.formats.hdf5 import read_nodes
            from viscx.skeleton.sites import node_sites

            counts["sites"] = int(len(np.unique(node_sites(read_nodes(group), epsilon))))
        return counts
    return {name: int(group[name].shape[0]) for name in group if hasattr(group[name], "shape") and group[name].shape}


@click.command(short_help="Show the counts, options and timings stored in a viscx file.")
@click.argument("path", metavar="FILE", type=click.Path(dir_okay=True))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info(path, as_json):
    """Print what FILE (written by `viscx build`) holds: counts per level, the
    build options and the time each stage took.

    \b
    viscx info cornell.h5
    viscx info cornell.h5 --json | python -m json.tool
    """
    summary = file_summary(path)
    if as_json:
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        return
    click.echo(f"{summary['file']}: viscx format {summary['format_version']} (written by viscx {summary['viscx_version']})")
    click.echo(f"  scene   {summary['scene']}  sha256 {summary['scene_sha256'][:16]}…")
    light = summary["options"].get("light")
    scoped = "" if not isinstance(light, dict) else "   built for one light: " + ", ".join(
        f"{k.replace('_', ' ')} {v}" for k, v in light.items())
    click.echo(f"  epsilon {summary['epsilon']:.6g}   levels: {', '.join(summary['levels'])}{scoped}")
    for level, counts in summary["counts"].items():
        click.echo(f"  [{level}]")
        for name, value in counts.items():
            click.echo(f"    {name:<20}{value:>10}")
    for name, (k, n, fraction) in summary.get("complete", {}).items():
        click.echo(f"  complete {name.replace('_', ' '):<12}{k:>10} of {n:<10}({100 * fraction:.2f} %)")
    click.echo("  groups  " + ", ".join(f"{name} ({n} faces)" for name, n in summary["groups"].items()))
    if summary["timings"]:
        click.echo("  timings " + ", ".join(f"{k} {v:.3f} s" for k, v in summary["timings"].items()))
