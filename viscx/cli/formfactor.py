"""``viscx formfactor``: exact and occlusion-exact form factors from a viscx file
(schemas in docs/queries.md)."""

import click

from viscx.cli.options import POINT, format_option, quiet


@click.command(short_help="Form factors: point to face, face to face, groups, the matrix.")
@click.argument("file", metavar="FILE", type=click.Path(dir_okay=True))
@click.option("--point", "point", type=POINT, default=None, metavar="X,Y,Z", help="A differential area at X,Y,Z (needs --normal).")
@click.option("--normal", "normal", type=POINT, default=None, metavar="NX,NY,NZ", help="Its normal (any length).")
@click.option("--from-face", "from_face", type=int, default=None, metavar="I", help="Emitting face I.")
@click.option("--from-side", "from_side", type=click.Choice(["front", "back"]), default="front", show_default=True,
              help="Side of the emitting face(s): front is the side of the face normal.")
@click.option("--to-face", "to_face", type=int, default=None, metavar="J", help="Receiving face J (both of its sides).")
@click.option("--from-group", "from_group", default=None, metavar="NAME", help="Emitting group (area-weighted).")
@click.option("--to-group", "to_group", default=None, metavar="NAME", help="Receiving group.")
@click.option("--matrix", is_flag=True, help="Every pair of face sides, sparse, written to -o F.h5.")
@click.option("--tol", type=float, default=None, metavar="T",
              help="Target on the absolute error estimate of each polygon-to-polygon form factor (default 1e-6); the output reports the estimate reached.")
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False), default=None,
              help="Where to write: the matrix (--matrix) as .h5, .npz (arrays and the group table) or .csv (the "
                   "group table), else .json or .msgpack (default: standard output).")
@format_option
@click.pass_context
def formfactor(ctx, file, point, normal, from_face, from_side, to_face, from_group, to_group, matrix, tol, output, fmt):
    """Form factors between parts of the scene in FILE (built by `viscx build`, with V2).

    \b
    Point to face (exact: Lambert's formula over the part of J the point sees, from
    its V-cells, Hoberock et al. §7.4):
      viscx formfactor cornell.h5 --point 278,1,280 --normal 0,1,0 --to-face 15
    Face to face (occlusion-exact integrand, adaptive quadrature, error estimate):
      viscx formfactor cornell.h5 --from-face 0 --to-face 15
    Groups (area-weighted over the emitting faces):
      viscx formfactor cornell.h5 --from-group floor --to-group light
    The matrix of every pair of face sides (sparse CSR, reciprocity and row sums reported;
    -o F.npz or F.csv for plain exports with the group-to-group table):
      viscx formfactor cornell.h5 --matrix -o F.h5

    Output: JSON {"F": value, ...} on standard output (or -o), msgpack with --format msgpack.
    """
    import time

    from viscx.errors import ViscxError
    from viscx.formats.queries import output_format, write_result
    from viscx.queries import formfactor as ff
    from viscx.queries.visibility import open_query

    point_mode = point is not None or normal is not None
    source_given = from_face is not None or from_group is not None
    target_given = to_face is not None or to_group is not None
    if sum([point_mode, source_given, bool(matrix)]) != 1:
        raise click.UsageError("give exactly one of --point/--normal, --from-face/--from-group, --matrix")
    if point_mode and (point is None or normal is None):
        raise click.UsageError("--point needs --normal (and --normal needs --point)")
    if from_face is not None and from_group is not None:
        raise click.UsageError("give --from-face or --from-group, not both")
    if to_face is not None and to_group is not None:
        raise click.UsageError("give --to-face or --to-group, not both")
    if not matrix and not target_given:
        raise click.UsageError("say what receives: --to-face J or --to-group NAME")
    if matrix and (target_given or output is None):
        raise click.UsageError("--matrix takes no --to-face/--to-group and needs -o F.h5")
    if tol is not None and not (tol > 0):
        raise click.UsageError("--tol must be positive")
    if matrix:
        fmt = fmt or "json"
    else:
        fmt = output_format(output, fmt)

    q = open_query(file)
    scene = q.scene
    n = scene.n_faces

    def check(face, option):
        if not 0 <= face < n:
            raise ViscxError(f"{option} {face} is out of range (the scene has {n} faces: 0 to {n - 1})")
        return face

    def targets():
        if to_face is not None:
            return [check(to_face, "--to-face")]
        return [int(f) for f in scene.group_faces(to_group)]

    t0 = time.perf_counter()
    if point_mode:
        faces = targets()
        result = ff.point_to_faces(q, point, normal, faces)
        result = {"F": result.pop("F"), **({"to_face": to_face} if to_face is not None else {"to_group": to_group}), **result}
    elif matrix:
        from viscx.formats.formfactors import write_export, write_matrix

        m = ff.form_factor_matrix(scene, tol=tol or ff.MATRIX_TOL, quiet=quiet(ctx))
        plain = str(output).lower().endswith((".npz", ".csv"))
        summary = (write_export if plain else write_matrix)(output, m, scene)
        write_result({"matrix": str(output), **summary}, None, fmt)
        return
    else:
        side = 1 if from_side == "front" else -1
        sources = [check(from_face, "--from-face")] if from_face is not None else [int(f) for f in scene.group_faces(from_group)]
        faces = targets()
        tol = tol or ff.DEFAULT_TOL
        if from_face is not None and to_face is not None:
            if from_face == to_face:
                raise ViscxError("--from-face and --to-face are the same face (a planar face does not see itself)")
            r = ff.face_to_face(scene, from_face, to_face, side_i=side, tol=tol)
            result = {"F": r["F"], "error": r["error"], "from_face": from_face, "from_side": from_side, "to_face": to_face,
                      "sides": r["sides"]}
        else:
            r = ff.group_to_group(scene, sources, faces, side_i=side, tol=tol)
            result = {"F": r["F"], "error": r["error"],
                      **({"from_face": from_face} if from_face is not None else {"from_group": from_group}),
                      "from_side": from_side,
                      **({"to_face": to_face} if to_face is not None else {"to_group": to_group}), "pairs": r["pairs"]}
        result["tol"] = tol
        result["seconds"] = round(time.perf_counter() - t0, 4)
    write_result(result, output, fmt)
    if point_mode and not result["complete"] and not quiet(ctx):
        click.echo("viscx: warning: some of the point's V-cells are incomplete; see docs/queries.md", err=True)
