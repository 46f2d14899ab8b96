"""Queries on a built complex: the visibility polyhedron of a point, shadows, form factors.

Each query reads what it needs from a viscx file (the scene and, for a point
stored by ``viscx build --point``, its V-cells) or computes a point's V-cells on
demand (:func:`viscx.skeleton.points.point_vcells`); it never rebuilds the
whole complex.
"""
