"""Furnished rooms and floor plans: the scenes people model, generated from a seed.

Everything is built from axis-aligned boxes that *touch*, as in a modeller: a desk
is a top resting on two side panels standing on the floor, cabinets stand on the
floor against a wall, a door is a gap in a wall with a lintel over it, a window a
gap with a sill below and a lintel above, a pillar runs from floor to ceiling. The
contacts are exact (shared planes, coincident vertices), so every configuration of
a building is there: faces meeting another face's interior along a line
(T-junctions), vertices lying on other faces, coplanar faces meeting at an edge.

Conventions: y is up, metres; boxes keep all six faces (a real model's panel has
its bottom face on the floor); groups name what a user selects (``floor``,
``ceiling``, ``wall_west`` …, ``light1`` …, ``desk3``, ``cabinet0``, ``pillar0``).
Deterministic in the seed and the counts.

>>> soup = furnished_room(n_desks=2, n_cabinets=1, n_dividers=1, n_lights=2, seed=1)
>>> soup.n_polygons  # 6 shell + 2 lights + 2 × 18 desks + 6 + 6
56
"""

import numpy as np

from viscx.scene import PolygonSoup

# The six quads of a box over its corners (x, y, z) in {lo, hi}³, corner index
# 4 x + 2 y + z; each quad counter-clockwise seen from outside.
_BOX_QUADS = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=np.float64)


class _Builder:
    """Polygons with group names, gathered in order."""

    def __init__(self):
        self.vertices, self.polygons, self.groups, self.names = [], [], [], {}

    def group(self, name):
        return self.names.setdefault(name, len(self.names))

    def quad(self, corners, name):
        base = len(self.vertices)
        self.vertices.extend(np.asarray(corners, dtype=np.float64).tolist())
        self.polygons.append(list(range(base, base + len(corners))))
        self.groups.append(self.group(name))

    def box(self, lo, hi, name):
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        corners = lo + _CORNERS * (hi - lo)
        base = len(self.vertices)
        self.vertices.extend(corners.tolist())
        for q in _BOX_QUADS:
            self.polygons.append([base + i for i in q])
            self.groups.append(self.group(name))

    def soup(self):
        sizes = [len(p) for p in self.polygons]
        return PolygonSoup(
            vertices=np.round(np.asarray(self.vertices, dtype=np.float64), 6),
            polygon_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
            polygon_vertices=np.concatenate(self.polygons).astype(np.int64),
            polygon_group=np.asarray(self.groups, dtype=np.int64),
            group_names=list(self.names),
        )


def _shell(b, width, height, depth):
    """Floor, ceiling and four walls of the box [0, width] × [0, height] × [0, depth], facing in."""
    w, h, d = width, height, depth
    b.quad([[0, 0, 0], [0, 0, d], [w, 0, d], [w, 0, 0]], "floor")
    b.quad([[0, h, 0], [w, h, 0], [w, h, d], [0, h, d]], "ceiling")
    b.quad([[0, 0, 0], [0, h, 0], [0, h, d], [0, 0, d]], "wall_west")
    b.quad([[w, 0, 0], [w, 0, d], [w, h, d], [w, h, 0]], "wall_east")
    b.quad([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], "wall_south")
    b.quad([[0, 0, d], [0, h, d], [w, h, d], [w, 0, d]], "wall_north")


def _light(b, centre, size, y, name):
    """A light quad at height y, facing down (a gap of a few cm under the ceiling)."""
    (cx, cz), (sx, sz) = centre, size
    b.quad([[cx - sx, y, cz - sz], [cx + sx, y, cz - sz], [cx + sx, y, cz + sz], [cx - sx, y, cz + sz]], name)


def boxes_and_quads(boxes=(), quads=()):
    """A soup of named boxes ``(lo, hi, name)`` and quads ``(corners, name)``: a few pieces of
    furniture placed exactly, for the tests' minimal scenes."""
    b = _Builder()
    for corners, name in quads:
        b.quad(corners, name)
    for lo, hi, name in boxes:
        b.box(lo, hi, name)
    return b.soup()


def desk_boxes(x0, z0, x1, z1, name="desk"):
    """The three boxes (lo, hi, name) of a desk on the footprint (x0, z0, x1, z1): a top
    resting on two panels flush with its ends (as :func:`furnished_room` builds them)."""
    top, legs, panel = 0.72, 0.69, 0.03
    out = [([x0, legs, z0], [x1, top, z1], name)]
    if x1 - x0 > z1 - z0:  # panels at the x ends, flush with the top's end faces
        out += [([x0, 0, z0], [x0 + panel, legs, z1], name), ([x1 - panel, 0, z0], [x1, legs, z1], name)]
    else:
        out += [([x0, 0, z0], [x1, legs, z0 + panel], name), ([x0, 0, z1 - panel], [x1, legs, z1], name)]
    return out


def _free(rect, placed, gap):
    """True when rect (x0, z0, x1, z1) keeps ``gap`` from every placed rect."""
    x0, z0, x1, z1 = rect
    return all(x1 + gap <= a0 or a1 + gap <= x0 or z1 + gap <= b0 or b1 + gap <= z0 for a0, b0, a1, b1 in placed)


def furnished_room(n_desks=16, n_cabinets=10, n_dividers=3, n_lights=4, size=(12.0, 3.0, 9.0), seed=0):
    """An office: a closed room with lights under the ceiling and touching furniture.

    Parameters
    ----------
    n_desks : int
        Desks: a 1.4 × 0.03 × 0.7 top resting on two 0.03-thick side panels flush
        with its ends (18 polygons each), turned by 0 or 90 degrees.
    n_cabinets : int
        Boxes 0.45 deep, 0.8–1.2 wide, 0.8–2.0 high, standing on the floor with their
        back against a wall (6 polygons each).
    n_dividers : int
        Screens 0.05 thick, 1.2–1.8 long, 1.2–1.6 high, standing on the floor.
    n_lights : int
        0.6 × 1.2 light quads 3 cm under the ceiling on a regular grid (``light1`` …).
    size : (3,) float
        The room's width (x), height (y) and depth (z).
    seed : int

    Returns
    -------
    PolygonSoup
        ``6 + n_lights + 18 n_desks + 6 (n_cabinets + n_dividers)`` polygons.
        Raises ValueError when the furniture does not fit the room.
    """
    rng = np.random.default_rng(seed)
    width, height, depth = (float(s) for s in size)
    b = _Builder()
    _shell(b, width, height, depth)
    nx = int(np.ceil(np.sqrt(n_lights * width / depth))) if n_lights else 0
    nz = int(np.ceil(n_lights / nx)) if n_lights else 0
    for i in range(n_lights):
        cx = (i % nx + 0.5) * width / nx
        cz = (i // nx + 0.5) * depth / nz
        _light(b, (cx, cz), (0.3, 0.6), height - 0.03, f"light{i + 1}")

    placed = []  # footprints (x0, z0, x1, z1)

    def place(w, d, against_wall, tries=10_000):
        for _ in range(tries):
            if against_wall:
                side = rng.integers(4)
                along = rng.uniform(0, (width if side < 2 else depth) - w)
                rect = {0: (along, 0.0, along + w, d), 1: (along, depth - d, along + w, depth),
                        2: (0.0, along, d, along + w), 3: (width - d, along, width, along + w)}[int(side)]
            else:
                turned = rng.random() < 0.5
                fw, fd = (d, w) if turned else (w, d)
                x0 = rng.uniform(0.1, width - fw - 0.1)
                z0 = rng.uniform(0.1, depth - fd - 0.1)
                rect = (x0, z0, x0 + fw, z0 + fd)
            rect = tuple(round(float(v), 6) for v in rect)
            if _free(rect, placed, 0.1):
                placed.append(rect)
                return rect
        raise ValueError(f"furnished_room: the furniture does not fit a {width} × {depth} room")

    for i in range(n_cabinets):
        x0, z0, x1, z1 = place(rng.uniform(0.8, 1.2), 0.45, against_wall=True)
        b.box([x0, 0, z0], [x1, rng.uniform(0.8, 2.0), z1], f"cabinet{i}")
    for i in range(n_desks):
        x0, z0, x1, z1 = place(1.4, 0.7, against_wall=False)
        for lo, hi, name in desk_boxes(x0, z0, x1, z1, f"desk{i}"):
            b.box(lo, hi, name)
    for i in range(n_dividers):
        x0, z0, x1, z1 = place(rng.uniform(1.2, 1.8), 0.05, against_wall=False)
        b.box([x0, 0, z0], [x1, rng.uniform(1.2, 1.6), z1], f"divider{i}")
    return b.soup()


def office(n_polygons, seed=0):
    """A furnished room of about ``n_polygons`` polygons (desks, cabinets, dividers, lights).

    The room grows with the furniture (constant density: about 6.75 m² of floor per
    desk, at least 12 × 9 m), so a 300-polygon office is the 12 × 9 × 3 m room of
    about 12 desks, 8 cabinets, 3 dividers and 4 lights.
    """
    n_desks = max(1, int(round((n_polygons - 10) * 0.74 / 18)))
    n_dividers = max(1, n_desks // 4)
    n_cabinets = max(1, int(round((n_polygons - 10 - 18 * n_desks - 6 * n_dividers) / 6)))
    scale = max(1.0, float(np.sqrt(n_desks / 16)))
    n_lights = max(4, int(round(4 * scale * scale)))
    return furnished_room(n_desks, n_cabinets, n_dividers, n_lights, size=(12.0 * scale, 3.0, 9.0 * scale), seed=seed)


def floor_plan(rooms=(2, 2), room_size=(5.0, 4.0), height=3.0, wall=0.2, doors=True, windows=True,
               pillars=1, seed=0):
    """Walls extruded from a grid plan of rooms, with doors, windows and pillars.

    The outer walls run along x at full length, the walls along z fit between them
    (end faces touching), interior walls likewise. An interior wall between two
    rooms gets a door (a 0.9 × 2.1 m gap under a lintel that touches the wall's
    pieces on both sides and the ceiling); outer walls get windows (a gap with a
    sill below and a lintel above). Pillars (0.3 × 0.3) run from floor to ceiling
    inside rooms. The floor and ceiling are one quad each over the whole plan; each
    room has a light quad under the ceiling (``light1`` …).

    Parameters
    ----------
    rooms : (2,) int
        Rooms along x and z.
    room_size : (2,) float
        Inner size of a room along x and z.
    height, wall : float
        Storey height and wall thickness.
    doors, windows : bool
    pillars : int
        Pillars per plan, placed in random rooms.
    seed : int

    Returns
    -------
    PolygonSoup
    """
    rng = np.random.default_rng(seed)
    nx, nz = rooms
    sx, sz = room_size
    t = float(wall)
    width = nx * sx + (nx + 1) * t
    depth = nz * sz + (nz + 1) * t
    b = _Builder()
    b.quad([[0, 0, 0], [0, 0, depth], [width, 0, depth], [width, 0, 0]], "floor")
    b.quad([[0, height, 0], [width, height, 0], [width, height, depth], [0, height, depth]], "ceiling")

    def wall_run(axis, fixed, start, stop, name, opening):
        """A wall along ``axis`` (0: x, 2: z) at the other coordinate ``fixed`` from start to
        stop, cut by an opening: None, ("door", centre) or ("window", centre)."""
        def box(a0, a1, y0, y1):
            lo, hi = [0.0, y0, 0.0], [0.0, y1, 0.0]
            other = 2 - axis
            lo[axis], hi[axis] = a0, a1
            lo[other], hi[other] = fixed, fixed + t
            b.box(lo, hi, name)

        if opening is None:
            box(start, stop, 0.0, height)
            return
        kind, centre = opening
        half = 0.45 if kind == "door" else 0.6
        a0, a1 = round(centre - half, 6), round(centre + half, 6)
        box(start, a0, 0.0, height)
        box(a1, stop, 0.0, height)
        top = 2.1 if kind == "door" else 2.2
        box(a0, a1, top, height)  # lintel, touching both pieces and the ceiling
        if kind == "window":
            box(a0, a1, 0.0, 0.9)  # sill

    def opening(kind, lo, hi, wanted):
        if not wanted or hi - lo < 2.0:
            return None
        return kind, round(float(rng.uniform(lo + 0.8, hi - 0.8)), 6)

    # walls along x: outer ones with windows, interior ones with doors, per room span
    for k in range(nz + 1):
        outer = k in (0, nz)
        z = k * (sz + t)
        name = "wall_south" if k == 0 else "wall_north" if k == nz else f"wall_x{k}"
        for i in range(nx):
            x0 = i * (sx + t)  # a piece covers the junction before its room span
            x1 = (i + 1) * (sx + t) + (t if i == nx - 1 else 0.0)
            lo, hi = i * (sx + t) + t, (i + 1) * (sx + t)
            wall_run(0, z, x0, x1, name, opening("window" if outer else "door", lo, hi, windows if outer else doors))
    # walls along z fit between the x walls
    for k in range(nx + 1):
        outer = k in (0, nx)
        x = k * (sx + t)
        name = "wall_west" if k == 0 else "wall_east" if k == nx else f"wall_z{k}"
        for j in range(nz):
            z0, z1 = j * (sz + t) + t, (j + 1) * (sz + t)
            wall_run(2, x, z0, z1, name, opening("window" if outer else "door", z0, z1, windows if outer else doors))
    light = (0.3, 0.6)  # half sizes along x and z
    for i in range(nx * nz):
        cx = (i % nx) * (sx + t) + t + sx / 2
        cz = (i // nx) * (sz + t) + t + sz / 2
        _light(b, (cx, cz), light, height - 0.03, f"light{i + 1}")
    for p in range(pillars):
        while True:  # drawn again where the pillar would pierce its room's light (seed 3 of 2 x 2 rooms)
            r = int(rng.integers(nx * nz))
            x0 = (r % nx) * (sx + t) + t + round(float(rng.uniform(0.5, sx - 0.8)), 6)
            z0 = (r // nx) * (sz + t) + t + round(float(rng.uniform(0.5, sz - 0.8)), 6)
            cx = (r % nx) * (sx + t) + t + sx / 2
            cz = (r // nx) * (sz + t) + t + sz / 2
            if x0 > cx + light[0] + 0.1 or x0 + 0.3 < cx - light[0] - 0.1 or \
                    z0 > cz + light[1] + 0.1 or z0 + 0.3 < cz - light[1] - 0.1:
                break
        b.box([x0, 0, z0], [x0 + 0.3, height, z0 + 0.3], f"pillar{p}")
    return b.soup()


def pv_field(rows=6, length=20.0, width=2.0, tilt=25.0, pitch=5.0, height=1.5, posts=4, post=0.1, margin=10.0):
    """Rows of tilted PV panels over the ground, on posts: the regular layout of a solar
    field, for bifacial view factors (a panel's back → the ground, its front → the sky).

    Each row is one two-sided quad (group ``row0`` …) ``length`` along x and ``width`` up
    the slope, tilted by ``tilt`` degrees about x, its upper edge towards -z (its front
    faces the sky and +z, the next row's back), its centre line ``height`` above the
    ground at z = k · pitch. Under each row stand
    ``posts`` boxes ``post`` wide on the ground (group ``post0`` … per row), each ending
    2 cm under the panel above its top: hovering edges, and the posts' feet touching the
    ground. The ground is one quad reaching ``margin`` past the field (group ``ground``).

    >>> pv_field(rows=2, posts=1).n_polygons  # ground + 2 panels + 2 × 6 post faces
    15
    """
    b = _Builder()
    t = np.radians(tilt)
    up = np.array([0.0, np.sin(t), -np.cos(t)])  # up the slope, towards -z
    x0, x1 = -margin, length + margin
    z0, z1 = -margin - width, (rows - 1) * pitch + margin + width
    b.quad([[x0, 0, z0], [x0, 0, z1], [x1, 0, z1], [x1, 0, z0]], "ground")
    for k in range(rows):
        c = np.array([0.0, height, k * pitch])
        lo, hi = c - 0.5 * width * up, c + 0.5 * width * up
        # counter-clockwise seen from the front (the sky): x, then up the slope
        b.quad([[0.0, lo[1], lo[2]], [length, lo[1], lo[2]], [length, hi[1], hi[2]], [0.0, hi[1], hi[2]]], f"row{k}")
    for k in range(rows):
        for p in range(posts):
            x = (p + 0.5) * length / posts - post / 2
            z = k * pitch - post / 2
            # the panel's underside above the post's top: lowest where z is largest
            top = height - (z + post - k * pitch) * np.tan(t) - 0.02
            b.box([x, 0.0, z], [x + post, round(top, 6), z + post], f"post{k}")
    return b.soup()


def shelving(units=3, bays=2, levels=4, bay=1.0, depth=0.4, height=2.0, board=0.02, upright=0.02, pitch=1.8,
             back=True, size=(8.0, 3.0, 7.0), n_lights=2):
    """A store room of shelving units: the regular layout of a library, a shop or a
    warehouse, whose boards touch their uprights along whole faces.

    Each unit (group ``shelf0`` …) runs along x from x = 1: ``bays + 1`` uprights
    (``upright`` thick, ``depth`` deep, ``height`` tall) standing on the floor, in each
    bay ``levels`` boards (``board`` thick) spanning between the uprights' inner faces
    (their end faces lie on them) and flush with their fronts and backs (coplanar faces
    meeting at an edge), the lowest 0.1 m up, the others evenly above it; a top board
    resting on the uprights' tops; with ``back``, a back panel 1 cm thick touching the
    uprights' and boards' backs. Unit 0 stands with its back against the south wall
    (z = 0), the others free-standing at a ``pitch`` along z. The room is a closed shell
    ``size`` = (x, y, z) with ``n_lights`` light quads (``light1`` …) 2 cm under the
    ceiling over the aisles.

    >>> shelving(units=1, bays=1, levels=1, n_lights=1).n_polygons  # 6 + 1 + 6 × (2 + 1 + 1 + 1)
    37
    """
    b = _Builder()
    width, room_h, room_d = size
    _shell(b, width, room_h, room_d)
    skin = 0.01 if back else 0.0
    x_end = 1.0 + bays * bay + (bays + 1) * upright
    for k in range(units):
        z0 = skin + k * pitch
        z1 = z0 + depth
        name = f"shelf{k}"
        xs = [1.0 + i * (bay + upright) for i in range(bays + 1)]
        for x in xs:
            b.box([x, 0.0, z0], [x + upright, height, z1], name)
        ys = [0.1 + i * (height - 0.1) / levels for i in range(levels)]
        for x in xs[:-1]:
            for y in ys:
                b.box([x + upright, y, z0], [x + upright + bay, y + board, z1], name)
        b.box([1.0, height, z0], [x_end, height + board, z1], name)
        if back:
            b.box([1.0, 0.0, z0 - skin], [x_end, height, z0], name)
    aisle = [skin + k * pitch + depth + (pitch - depth) / 2 for k in range(units)]
    for k in range(n_lights):
        cz = aisle[k % len(aisle)]
        cx = 1.0 + (x_end - 1.0) * (k // len(aisle) + 0.5) / max(1, -(-n_lights // len(aisle)))
        _light(b, (cx, cz), (0.6, 0.15), room_h - 0.02, f"light{k + 1}")
    return b.soup()


def write_obj(soup, path):
    """Write a soup as OBJ, one ``o`` group per group name (vertices as written, 6 decimals)."""
    lines = ["# viscx benchmark scene (benchmarks/buildings.py)"]
    n = 0
    for g, name in enumerate(soup.group_names):
        polys = np.flatnonzero(soup.polygon_group == g)
        if len(polys) == 0:
            continue
        lines.append(f"o {name}")
        for p in polys:
            idx = soup.polygon_vertices[soup.polygon_offsets[p]:soup.polygon_offsets[p + 1]]
            lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in soup.vertices[idx]]
            lines.append("f " + " ".join(str(n + 1 + i) for i in range(len(idx))))
            n += len(idx)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("kind", choices=["office", "plan", "pv", "shelves"])
    parser.add_argument("-n", "--polygons", type=int, default=300, help="office: about this many polygons")
    parser.add_argument("--rooms", type=int, nargs=2, default=(2, 2), help="plan: rooms along x and z")
    parser.add_argument("--pv-rows", type=int, default=6, help="pv: rows of panels")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("-o", "--output", required=True)
    args = parser.parse_args()
    soup = {"office": lambda: office(args.polygons, args.seed), "plan": lambda: floor_plan(tuple(args.rooms), seed=args.seed),
            "pv": lambda: pv_field(rows=args.pv_rows), "shelves": lambda: shelving()}[args.kind]()
    write_obj(soup, args.output)
    print(f"{args.output}: {soup.n_polygons} polygons")
