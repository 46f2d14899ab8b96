"""Scoped builds: the part of V0 and V1 that holds given generators (an area light's
outline vertices and edges), with the full build's definitions.

An arc family (EEE, VE, XE) is *in scope* when one of its generators is a scope vertex
or a scope edge. The arcs of a family are decided within it (events, samples,
refinement, merging: :mod:`viscx.skeleton.arcs`), so the scoped build gives exactly
the full build's arcs of those families once it has every event on them. Their node
events are the nodes whose generators hold the family's (docs/skeleton.md, "Which
families"):

* VEE (v, e1, e2) lies on VE (v, e1), VE (v, e2) and EEE (e_v, e1, e2) for the edges
  e_v at v; E4 on the EEE families of three of its edges; VV (u, v) on VE (u, e) for
  the edges e at v. With the scope's vertices closed over its edges' endpoints, a node
  on a family in scope holds a scope vertex or edge.
* A node whose vertex w is a T-junction inside an edge E also seeds the families
  through E (:func:`viscx.skeleton.arcs.family_incidences`, ``through``): nodes at the
  vertices lying inside a scope edge are kept too.

So V0 in scope is the nodes with a generator in :attr:`Scope.node_vertices` or
:attr:`Scope.edges`, judged by the one node definition
(:func:`viscx.skeleton.nodes.validate_candidates`) on the full builder's candidates
for those tuples (the same floats): a subset of the full V0, in its order. The
families of V1 in scope come from them, the seeded families (same-plane VE, pencils of
touched planes, XE) filtered to the scope.
"""

from dataclasses import dataclass

import numpy as np

from viscx.arrays import unique_rows
from viscx.skeleton.generators import edges_through_vertices


@dataclass
class Scope:
    """Generators a scoped build keeps.

    Attributes
    ----------
    vertices : (n_vertices,) bool
        Scope vertices (the edges' endpoints included).
    edges : (n_edges,) bool
        Scope edges.
    node_vertices : (n_vertices,) bool
        ``vertices`` and the vertices lying strictly inside a scope edge.
    """

    vertices: np.ndarray
    edges: np.ndarray
    node_vertices: np.ndarray

    @staticmethod
    def of(scene, vertices=(), edges=()):
        """The scope of the given vertex and edge ids of ``scene``."""
        ev = scene.half_edges.edge_vertices
        edges = np.asarray(edges, np.int64)
        vmask = np.zeros(scene.n_vertices, bool)
        vmask[np.asarray(vertices, np.int64)] = True
        vmask[ev[edges].ravel()] = True
        emask = np.zeros(len(ev), bool)
        emask[edges] = True
        jo, je = edges_through_vertices(scene)
        owner = np.repeat(np.arange(scene.n_vertices), np.diff(jo))
        nmask = vmask.copy()
        nmask[owner[emask[je]]] = True
        return Scope(vmask, emask, nmask)

    def _vertex(self, ids, mask):
        ids = np.asarray(ids, np.int64)
        ok = (ids >= 0) & (ids < len(mask))
        return ok & mask[np.where(ok, ids, 0)]

    def _edge(self, ids):
        ids = np.asarray(ids, np.int64)
        ok = ids >= 0
        return ok & self.edges[np.where(ok, ids, 0)]

    def nodes(self, kind, generators):
        """(m,) bool: node tuples (kind E4, VEE or VV; generators (m, 4) as
        :class:`viscx.skeleton.nodes.Nodes`) with a generator in scope."""
        from viscx.skeleton.nodes import SLOT_IS_VERTEX

        g = np.asarray(generators, np.int64).reshape(-1, 4)
        vertex_slot = SLOT_IS_VERTEX[np.asarray(kind, np.int64)]
        hit = np.where(vertex_slot, self._vertex(g, self.node_vertices), self._edge(g))
        return hit.any(axis=1)

    def families(self, kind, generators):
        """(m,) bool: arc families (kind EEE, VE or XE; generators (m, 3) as
        :class:`viscx.skeleton.arcs.Arcs`) with a generator in scope."""
        from viscx.skeleton.arcs.kinds import VE

        g = np.asarray(generators, np.int64).reshape(-1, 3)
        ve = np.asarray(kind) == VE
        first = np.where(ve, self._vertex(g[:, 0], self.vertices), self._edge(g[:, 0]))
        return first | self._edge(g[:, 1]) | self._edge(g[:, 2])


def _side_codes(lo, hi, x_lo, x_hi):
    """(n,) int: per axis 0 when a box (lo, hi (n, 3)) lies below [x_lo, x_hi], 2 above,
    1 across, as the base-3 digits of one code (0..26)."""
    side = np.where(hi < x_lo, 0, np.where(lo > x_hi, 2, 1))
    return side @ np.array([9, 3, 1])


def _compatible_codes():
    """(27, 27) bool: two side codes whose joint box meets the box on every axis (not
    both below, not both above)."""
    digits = np.array([[c // 9, c // 3 % 3, c % 3] for c in range(27)])
    a, b = digits[:, None, :], digits[None, :, :]
    return (~(((a == 0) & (b == 0)) | ((a == 2) & (b == 2)))).all(axis=2)


def pairs_near(s_lo, s_hi, lo1, hi1, lo2, hi2, same=False):
    """The outer pairs a scoped scan visits (:func:`viscx.skeleton.candidates.fast_candidates`):
    pairs (i, j) of an item of set 1 and one of set 2 whose joint bounding box meets the
    box of a scope generator.

    A node in scope has a scope generator on its line between (or at) its two outer
    generators, so inside their hull and so inside their joint box. The pairs are found
    light-centred, per scope generator, by the side of its box each item lies on along
    each axis (below, across, above): a joint box misses it only when both items lie
    below, or both above, on some axis. So items far from the light pair only with the
    few reaching it (the light's own edges, a wall across its height), and no pair of
    the scene's generators is visited otherwise.

    Parameters
    ----------
    s_lo, s_hi : (k, 3) float
        Boxes of the scope generators (padded by the scans' tolerance).
    lo1, hi1 : (n1, 3) float
    lo2, hi2 : (n2, 3) float
        Boxes of the items.
    same : bool
        One set (set 2 is set 1): pairs i < j.

    Returns
    -------
    first : (m,) int64
        The items of set 1 with a pair, increasing.
    (offsets, partners) : (n1 + 1,) int64, (p,) int64
        Item i's partners, increasing, at ``partners[offsets[i]:offsets[i + 1]]``.
    """
    ok = _compatible_codes()
    parts_i, parts_j = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for x_lo, x_hi in zip(s_lo, s_hi):
        groups = []
        for lo, hi in ((lo1, hi1), (lo2, hi2)):
            code = _side_codes(lo, hi, x_lo, x_hi)
            order = np.argsort(code, kind="stable")
            groups.append((order, np.searchsorted(code[order], np.arange(28))))
        (o1, b1), (o2, b2) = groups
        for p, q in zip(*np.nonzero(ok)):
            g1, g2 = o1[b1[p] : b1[p + 1]], o2[b2[q] : b2[q + 1]]
            if len(g1) and len(g2):
                parts_i.append(np.repeat(g1, len(g2)))
                parts_j.append(np.tile(g2, len(g1)))
    i, j = np.concatenate(parts_i), np.concatenate(parts_j)
    if same:
        i, j = np.minimum(i, j), np.maximum(i, j)
        i, j = i[i < j], j[i < j]
    pairs = unique_rows(np.stack([i, j], axis=1).astype(np.int64))[0].reshape(-1, 2)
    offsets = np.searchsorted(pairs[:, 0], np.arange(len(lo1) + 1)).astype(np.int64)
    return np.unique(pairs[:, 0]), (offsets, np.ascontiguousarray(pairs[:, 1]))
