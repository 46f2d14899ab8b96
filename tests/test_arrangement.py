"""The convex pieces of a plane cut along segments (:mod:`viscx.geometry.arrangement`),
against what an arrangement must be: a partition of the input (areas and point location),
convex counter-clockwise pieces, no segment's line through a piece's interior where the
segment runs over it, and each part labelled with the piece it was cut from."""

import numpy as np
import pytest

from viscx.geometry.arrangement import cut_pieces, flat_to_pieces, piece_centres, pieces_to_flat, segments_crossing
from viscx.queries.formfactor import cut_along, cut_flat


def _area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _inside(p, pts, eps):
    """(m,) bool: the points within the convex counter-clockwise polygon p (eps inwards)."""
    e = np.roll(p, -1, axis=0) - p
    rel = pts[:, None, :] - p[None]
    return np.all(e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0] > eps, axis=1)


def _random_case(rng):
    pieces = []
    for _ in range(rng.integers(1, 12)):
        c = rng.uniform(-1, 1, 2)
        t = c + rng.uniform(-0.4, 0.4, (3, 2))
        pieces.append(t if _area(t) > 0 else t[::-1])
    seg = rng.uniform(-1.3, 1.3, (rng.integers(1, 40), 2, 2))
    seg[:4, 1, 1] = seg[:4, 0, 1]  # some horizontal
    seg[4:6, 0] = pieces[0][0]  # some through a corner
    return pieces, seg


@pytest.mark.parametrize("seed", range(20))
def test_pieces_partition_the_input_and_no_segment_runs_through_one(seed):
    rng = np.random.default_rng(seed)
    pieces, seg = _random_case(rng)
    eps = 1e-9
    verts, ptr, owner = cut_flat(*pieces_to_flat(pieces), seg, eps)
    out = flat_to_pieces(verts, ptr)
    assert len(owner) == len(out) >= len(pieces)
    # areas: each input piece is the union of its parts
    parts_area = np.bincount(owner, weights=[_area(q) for q in out], minlength=len(pieces))
    assert np.allclose(parts_area, [_area(p) for p in pieces], rtol=0, atol=1e-12)
    for q in out:
        assert _area(q) > 0
        e = np.roll(q, -1, axis=0) - q
        turn = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        assert np.all(turn > -1e-12)  # convex, counter-clockwise
    # point location (the input pieces may overlap): a point strictly inside an input piece
    # lies in a part of it, in the interior of one at most, and in no part of it if outside
    pts = rng.uniform(-1.5, 1.5, (4000, 2))
    for k, p in enumerate(pieces):
        parts = [q for q, o in zip(out, owner) if o == k]
        inner = _inside(p, pts, 1e-7)
        closed = np.array([_inside(q, pts, -1e-12) for q in parts])  # (n, m)
        open_ = np.array([_inside(q, pts, 1e-12) for q in parts])
        assert np.all(closed[:, inner].any(axis=0))
        assert np.all(open_.sum(axis=0) <= 1)
        assert not np.any(closed[:, ~_inside(p, pts, -1e-7)])
    # no segment's line crosses a part's interior along a chord overlapping the segment
    for a, b in seg:
        d = (b - a) / np.linalg.norm(b - a)
        for q in out:
            s = (q - a) @ np.array([d[1], -d[0]])
            if s.max() > 1e-7 and s.min() < -1e-7:
                # the line crosses it: then only outside the segment
                t = (q - a) @ d
                length = np.linalg.norm(b - a)
                cross = []
                for i in range(len(q)):
                    r = (i + 1) % len(q)
                    if (s[i] > 0) != (s[r] > 0):
                        cross.append(t[i] + (t[r] - t[i]) * s[i] / (s[i] - s[r]))
                assert min(max(cross), length) - max(min(cross), 0.0) <= 1e-7


def test_limit_and_labels():
    """Past ``limit`` pieces the cut stops (None from :func:`cut_along`), and a label given
    to a piece is kept by its parts."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    seg = np.array([[[x, -1.0], [x, 2.0]] for x in np.linspace(0.05, 0.95, 10)])
    assert len(cut_along([square], seg, 1e-9)) == 11
    assert cut_along([square], seg, 1e-9, limit=5) is None
    verts, ptr = pieces_to_flat([square, square + 3.0])
    verts, ptr, owner, complete = cut_pieces(verts, ptr, np.array([7, 9]), seg, np.full(len(seg), 3.0), 1e-9, -1)
    assert complete and owner.tolist() == [7] * 11 + [9]
    assert np.allclose(np.sort(piece_centres(verts, ptr)[:11, 0]), np.concatenate([[0.025], np.linspace(0.1, 0.9, 9),
                                                                                 [0.975]]))
    # a segment shorter than eps cuts nothing; one whose chord misses the piece neither
    assert len(cut_along([square], np.array([[[0.5, -1.0], [0.5, -0.5]]]), 1e-9)) == 1


@pytest.mark.parametrize("seed", range(3))
def test_segments_crossing_is_what_it_says_and_a_superset_of_the_cuts(seed):
    """segments_crossing against a plain loop over its predicate (the line leaves corners
    more than eps on both sides, the triangle's extent along it overlaps the segment by
    more than eps), on random segments and triangles, segments along triangles' edges and
    through their corners among them; and every triangle that cut_pieces cuts with a
    segment is one it names (what the gap search relies on)."""
    rng = np.random.default_rng(seed)
    tri = rng.uniform(0, 1, (40, 3, 2))
    seg = rng.uniform(-0.2, 1.2, (200, 2, 2))
    seg[:20] = tri[:20, :2]  # along an edge
    seg[20:40, 0] = tri[20:40, 0]  # from a corner
    seg[40:45, 1] = seg[40:45, 0]  # of no length
    eps = 1e-9
    got = segments_crossing(seg, tri, eps)
    want = np.zeros_like(got)
    for i, (a, b) in enumerate(seg):
        length = float(np.hypot(*(b - a)))
        if not length > eps:
            continue
        d = (b - a) / length
        for r, t in enumerate(tri):
            side = [float(d[0] * (p - a)[1] - d[1] * (p - a)[0]) for p in t]
            along = [float(np.dot(p - a, d)) for p in t]
            want[i, r] = max(side) > eps and min(side) < -eps and max(along) > eps and min(along) < length - eps
    assert np.array_equal(got, want)
    assert 0 < got.sum() < got.size and not got[:20].diagonal().any() and not got[40:45].any()
    for i in range(len(seg)):
        for r in range(len(tri)):
            verts, ptr = pieces_to_flat([tri[r][::1 if _ccw(tri[r]) else -1]])
            length = np.array([np.hypot(*(seg[i, 1] - seg[i, 0]))])
            _, parts, _, _ = cut_pieces(verts, ptr, np.zeros(1, np.int64), seg[i:i + 1], length, eps, 10)
            if len(parts) > 2:
                assert got[i, r], (i, r)


def _ccw(t):
    return (t[1, 0] - t[0, 0]) * (t[2, 1] - t[0, 1]) - (t[1, 1] - t[0, 1]) * (t[2, 0] - t[0, 0]) > 0
