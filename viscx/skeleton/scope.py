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
