"""``viscx render``: images of the direct illumination from an area light."""

from pathlib import Path

import click

from viscx.cli.options import POINT, at_least, file_argument, light_options, output_option, positive, quiet, scene_options

#: what one pixel costs while rendering: radiance and its tone-mapped copies, the primary
#: rays and hits, the region ids (float64 and int64 arrays of a few columns each)
BYTES_PER_PIXEL = 256


@click.command(short_help="Render direct illumination: exact, from sparse samples, or Monte Carlo.")
@file_argument
@click.option("--camera", "eye", type=POINT, required=True, metavar="X,Y,Z", help="The eye.")
@click.option("--look-at", "look_at", type=POINT, required=True, metavar="X,Y,Z", help="The point looked at.")
@click.option("--up", "up", type=POINT, default="0,1,0", show_default=True, metavar="X,Y,Z", help="Up direction.")
@click.option("--fov", type=float, default=39.3, show_default=True, metavar="DEG", help="Vertical field of view.")
@click.option("--size", type=(int, int), default=(512, 512), show_default=True, metavar="W H", help="Image size in pixels.")
@light_options
@click.option("--radiance", type=POINT, default=None, metavar="R,G,B",
              help="The light's emitted radiance. Default: its material's Ke.")
@click.option("--samples", type=int, default=None, metavar="N", callback=at_least(0),
              help="Sparse reconstruction: evaluate the illumination at N samples (plus the regions' corners) "
              "and interpolate inside each region.")
@click.option("--reference", type=int, default=None, metavar="K", callback=at_least(1),
              help="Monte Carlo reference with K light samples per pixel (embree shadow rays) instead.")
@click.option("--show-regions", is_flag=True, help="Draw the regions' boundaries on the PNG.")
@click.option("--exposure", type=float, default=None, metavar="E", callback=positive,
              help="Scale radiance by E before the sRGB curve. Default: the 99th percentile of the lit "
              "pixels' luminance maps to white.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of --reference.")
@output_option("The PNG to write; the linear radiance goes beside it as .npy (float32, h×w×3) and .pfm "
               "(and, with --reference, its standard error as .stderr.npy).")
@scene_options
@click.pass_context
def render(ctx, file, eye, look_at, up, fov, size, light_face, light_group, radiance, samples, reference, show_regions,
           exposure, seed, output, epsilon, relative_epsilon, weld):
    """Render the direct illumination of the scene in FILE (built by `viscx build`) from an
    area light (Hoberock et al. §7.4–7.5). Primary visibility is ray cast; each pixel's radiance is
    exact: the part of the light its point sees (polygon clipping against the occluders
    that the light's discontinuity-mesh region of the point names) and Lambert's formula,
    evaluated region by region. Faces are Lambertian (OBJ Kd); the light emits its Ke from
    its front. The PNG is tone mapped (sRGB); the .npy and .pfm beside it are linear.

    \b
    viscx build sample_scenes/cornell_box.obj -o cornell.h5
    viscx render cornell.h5 --camera 278,273,-800 --look-at 278,273,0 --light-group light -o cornell.png
    viscx render cornell.h5 --camera 278,273,-800 --look-at 278,273,0 --light-group light \\
        --samples 500 --show-regions -o cornell_sparse.png
    viscx render cornell.h5 --camera 278,273,-800 --look-at 278,273,0 --light-group light \\
        --reference 256 -o cornell_mc.png
    viscx render sample_scenes/cornell_box.obj --camera 278,273,-800 --look-at 278,273,0 \\
        --light-group light -o cornell.png

    FILE is a viscx file (a full build, or one built for this light with `viscx build
    --light-group`) or a scene file: then only the nodes and arcs of the light's families
    are built (the full build's; --epsilon/--relative-epsilon/--weld as `viscx build`).
    """
    import json

    import numpy as np

    from viscx.api import render_light
    from viscx.errors import ViscxError
    from viscx.formats.images import write_npy, write_pfm, write_png
    from viscx.memory import memory_budget
    from viscx.queries.discontinuities import open_light_query
    from viscx.render.direct import emitter
    from viscx.progress import bar
    from viscx.render.image import picture

    out = Path(output)
    if out.suffix.lower() != ".png":
        raise ViscxError(f"-o {output}: the image is written as PNG; name it *.png")
    need = max(size[0], 1) * max(size[1], 1) * BYTES_PER_PIXEL
    if need > memory_budget():
        raise ViscxError(f"--size {size[0]} {size[1]} needs about {need / 2**30:.0f} GiB, over the memory budget "
                         f"({memory_budget() / 2**30:.1f} GiB; VISCX_MEMORY_BUDGET)")
    # the discontinuity mesh (and so, from a scene file, the light's scoped build) only
    # where regions are asked for: the exact image and Monte Carlo need the scene alone
    regions = samples is not None or show_regions
    cx = open_light_query(file, light_face, light_group, check=lambda scene, light: emitter(scene, light, radiance),
                          scene_only=not regions, epsilon=epsilon, relative_epsilon=relative_epsilon, weld=weld)
    with bar(total=size[0] * size[1], desc="monte carlo", quiet=quiet(ctx) or reference is None, unit="px") as b:
        result = render_light(cx, eye, look_at, up, fov, size, light_face=light_face, light_group=light_group,
                              radiance=radiance, samples=samples, reference=reference, seed=seed, progress=b.update,
                              regions=regions)
    rgb, used = picture(result, result.light_faces, exposure, show_regions)
    stem = out.with_suffix("")
    write_npy(stem.with_suffix(".npy"), result.radiance.astype(np.float32))
    write_pfm(stem.with_suffix(".pfm"), result.radiance)
    if result.stderr is not None:
        write_npy(Path(f"{stem}.stderr.npy"), result.stderr.astype(np.float32))
    write_png(out, rgb)
    if not quiet(ctx):
        click.echo(json.dumps({"image": str(out), "exposure": used, **result.stats}), err=True)
