"""Flatland: the 2-D visibility complex of disjoint convex objects and radiosity (Orti et al.).

- :mod:`viscx.flatland.scene`: objects (circles, convex polygons), JSON/SVG/DXF loading.
- :mod:`viscx.flatland.kernels`: numba kernels (support functions, bitangents, grid walks).
- :mod:`viscx.flatland.complex`: vertices, edges, faces, incidences, form factors (2 ways).
- :mod:`viscx.flatland.mesh`: discontinuity mesh, element form factors, radiosity.
- :mod:`viscx.flatland.dynamic`: update after moving one object.
- :mod:`viscx.flatland.plot`: pictures (matplotlib, optional).

File layouts live in :mod:`viscx.formats.flatland`; see ``docs/flatland.md``.
"""
