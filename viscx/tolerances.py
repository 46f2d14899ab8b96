"""Every tolerance of viscx, defined once, with what it is.

Three scales (docs/skeleton.md, "Robustness"):

* **Rounding** (dimensionless): angles, cosines and relative sizes below which float64
  arithmetic cannot tell two things apart (parallel directions, a point on an edge).
* **Epsilon** (scene units, ``scene.epsilon``): Duguet & Drettakis's robust epsilon
  visibility; values named ``*_EPSILONS`` are multiples of it.
* **Weld** (scene units, ``scene.weld_tolerance``): the cleaning of the input.

Coupled values are computed from their sources here (e.g. the joins of V2 span two of
V1's merges), so that changing one moves the others. Modules import what they use by
name; a test may still monkeypatch the module's copy.
"""

# --------------------------------------------------------------------------------------
# the scene (relative to the bounding-box diagonal)

#: Default weld (and coplanarity) tolerance.
DEFAULT_WELD = 1e-7
#: Default robustness epsilon.
DEFAULT_EPSILON = 1e-6
#: Largest robustness epsilon, relative to the scene's bounding-box diagonal: an epsilon
#: near the scene's size makes every line "graze" everything (kernels sized by it overflow).
MAX_RELATIVE_EPSILON = 1e-2

# --------------------------------------------------------------------------------------
# rounding

#: Angle (radians; also a cosine or sine, which agree at this size) within which two
#: directions are one, a line lies in a plane or is tangent at a wedge's side: far above
#: the rounding of unit directions (1e-16), far below any angle of a scene's features.
ANGLE_TOLERANCE = 1e-9
#: Relative size of a cross product or determinant (to the product of its factors' sizes)
#: below which they are parallel, or a linear system singular: rounding only.
PARALLEL_TOLERANCE = 1e-12
#: Slack on a parameter s in [0, 1] along an edge (an event on the edge's end).
PARAMETER_SLACK = 1e-9

# --------------------------------------------------------------------------------------
# ray casting (viscx.raycast, viscx.grid)

#: Barycentric slack: points on a triangle's edge are on the (closed) triangle.
BARY_SLACK = 1e-12
#: Rays closer to parallel than this (|cos| to the normal) graze a triangle's
#: plane and never hit it: rounding alone puts rays built in a plane ~1e-14 off it.
PARALLEL_COSINE = 1e-12
#: Enlargement of the bounding box where sky ends are placed (design decisions, Sky: docs/references.md).
SKY_MARGIN = 0.01
#: An embree hit is clear-cut when float64 puts it this far inside its triangle
#: (smallest barycentric coordinate) ...
CLEAR_MARGIN = 1e-6
#: ... and the ray meets the triangle's plane at least this steeply (|cos|).
CLEAR_COSINE = 1e-4

# --------------------------------------------------------------------------------------
# V0: nodes (viscx.skeleton.nodes, viscx.skeleton.candidates)

#: Slack (relative to the scene's diagonal) within which a hit point lies on another face,
#: for the ties of :func:`viscx.skeleton.nodes.first_faces`: rounding of the hit point only.
TIE_SLACK = 1e-12
#: Hits closer than this (relative to the diagonal) to their triangle's boundary, by their
#: smallest barycentric coordinate times the triangle's longest side, are checked for ties
#: (they may lie on an edge shared with other faces).
TIE_MARGIN = 10 * TIE_SLACK
#: A ray lies in a face's plane when |cos| to its normal is at most this (tangency's angle
#: tolerance) and its origin is within the weld tolerance of the plane.
GRAZE_COSINE = ANGLE_TOLERANCE
#: Depth, in epsilons, a segment must reach inside a solid to be blocked by it.
SOLID_DEPTH = 8.0
#: Other components' generator edges must stay this many epsilons away from a blocking solid.
ISOLATION = 3.0
#: Inflation of the hull of two generators, in epsilons (the proof needs 2).
HULL_TOL = 4.0
#: Slack on the line parameters (s, t on the outer pair, u on an inner edge, λ along
#: the segment) of the candidates' exact filters, on top of the ε margins: rounding of
#: their closed forms where they are well conditioned (where they are not, the filters
#: accept).
PARAM_SLACK = 1e-7
#: Margin, in epsilons, kept from an edge's ends and between consecutive points by
#: the exact filters (validation demands more than 1 ε; the rest covers the
#: difference between these closed forms and the reference's constructions).
END_MARGIN = 0.4
#: Relative size of the triple product below which two lines count as coplanar
#: when pruning tuples whose solutions form a family: far tighter than the
#: exact solver's own test, so that the pruning never drops a solvable tuple.
COPLANAR = 1e-14
#: Relative size below which a side-product form counts as identically zero
#: (the edge lies in the plane of the outer pair, to rounding).
IN_PLANE = 1e-14
#: How far, in epsilons, a generator point of the closed forms may lie from the
#: reference's when a scan prunes a line that crosses a solid (the solids' planes
#: move inwards by this, plus PARAM_SLACK of the edge's length): more than the
#: END_MARGIN allowance the other filters already rely on.
POINT_SLACK = 1.0

# --------------------------------------------------------------------------------------
# V1: arcs (viscx.skeleton.arcs)

#: Events of one family closer than this many epsilons along its parameter edge are one
#: event (single linkage: a run of events each this close to the next merges).
MERGE_EPSILONS = 4
#: Besides its middle, each interval between events is sampled this many epsilons (along
#: the parameter edge) from each end (at most a tenth of the interval).
END_SAMPLE_EPSILONS = 20
#: A transition of a VE family is moved onto the event that explains it (its line through a
#: vertex, a junction or an edge's crossing with the family's plane) when that event lies
#: within this many epsilon along the family's edge.
SNAP = 20
#: A transition of an EEE family whose line meets one of its edges within this many epsilon (length)
#: of an endpoint, next to its interval's event at that endpoint with nothing valid between,
#: is node condition 5's (an edge point within epsilon of its end): the arc ends at the event
#: (docs/skeleton.md, "Arcs"). The bisection puts such a cut at 1 epsilon within rounding.
ENDPOINT_ZONE = 1.5
#: Angle (radians) by which a VE line is turned about its vertex, off the plane of the vertex
#: and the edge, to find the V-cells on either side (half-cells): far above the rounding of
#: directions (1e-16) and ANGLE_TOLERANCE, far below the thinnest cells of the samples
#: (about 1e-4 rad between the Cornell light and the ceiling, seen from a wall).
PROBE_ANGLE = 1e-8
#: Margin (radians) of the direction ranges that pair a same-plane VE family with the points
#: of its plane its lines can pass (the exact parameter test decides): far above rounding.
ANGLE_MARGIN = 1e-6

# --------------------------------------------------------------------------------------
# V2: V-cells on a vertex's direction sphere (viscx.skeleton.vcells)

#: Chord on the unit sphere below which an element's end and another's start are one point:
#: V1 puts arc ends at events computed per family (nodes: rounding; transitions: bisection
#: to ~1e-12 in s), far below this.
JOIN_CHORD = 1e-7
#: Open chains whose ends lie this many epsilon apart along their edges are joined
#: (:func:`viscx.skeleton.vcells.join_open_chains`): two families meeting at a corner may
#: keep events two links of a V1 merge apart (docs/skeleton.md, "V-cells", for the gaps
#: measured on the random_boxes cities).
JOIN_EPSILONS = 2 * MERGE_EPSILONS
#: Largest chord such a join spans (JOIN_EPSILONS epsilon seen from an edge 8000 epsilon
#: from the vertex).
JOIN_LIMIT = 1e-3
#: A gap of a loop whose two elements' great circles meet within this many times its chord
#: of both its ends has its corner there (:func:`viscx.skeleton.vcells.sphere_turning_sums`).
CORNER_REACH = 2.0
#: ... as has a gap whose direction lies within this angle (radians) of the reverse of the
#: incoming element's tangent or of the outgoing one's (it runs back along that element).
SPIKE_ANGLE = 1e-6
#: A loop's corner turning within this angle of ±π is a cusp; where its ends lie farther
#: apart than CUSP_GAP (a chord far above the ends' rounding) the gap's side decides the turn.
CUSP_ANGLE = 1e-3
CUSP_GAP = 1e-10
#: Angle by which a loop's reference point lies left of the middle of its longest arc
#: (:func:`viscx.skeleton.vcells.reference_points`).
SPHERE_REFERENCE_OFFSET = 1e-8
#: A vertex's cells cover its sphere when their solid angles sum to 4π within this.
SPHERE_COVER_TOLERANCE = 1e-6

# --------------------------------------------------------------------------------------
# V2: EE-cells on an edge pair's square (viscx.skeleton.eecells)

#: Ends of two elements closer than this many epsilon (along the edges) are one point of
#: the square: two links of a V1 merge, as JOIN_EPSILONS on the sphere.
SQUARE_JOIN_EPSILONS = 2 * MERGE_EPSILONS
#: ... and closer than this many epsilon, the same event (rounding apart: V1 puts the ends of
#: arcs meeting at one event within 1e-5 of it, merged events 1e-3 of it apart or more,
#: measured on random_boxes(300)); FormLoops links those first (docs/skeleton.md, "EE-cells", rule 17).
SQUARE_SAME_POINT_EPSILONS = 1e-3
#: A loop's reference point lies this far (square units, at most a thousandth of the
#: element) left of its longest element.
SQUARE_REFERENCE_OFFSET = 1e-9
#: A loop is closed when its winding is ±2π within this (else it is an open chain).
WINDING_TOLERANCE = 1e-6
#: A pair's cells cover the square when their areas sum to 1 within this.
SQUARE_COVER_TOLERANCE = 1e-6

# --------------------------------------------------------------------------------------
# queries (viscx.queries.discontinuities)

#: Chordal tolerance of the EEE traces (conic arcs as polylines), in epsilons.
CHORD_TOLERANCE = 10.0
#: Split points of one receiver closer than this many epsilons are one vertex.
SPLIT_SNAP = 10.0

# --------------------------------------------------------------------------------------
# files (viscx.formats.diff, ``viscx diff``)

#: Default relative tolerance of ``viscx diff`` for float values.
DEFAULT_RTOL = 1e-9
#: Default absolute tolerance of ``viscx diff`` for float values: a floor for values that
#: should be zero (normal components, offsets of planes through the origin) and come out as
#: ±1e-17 on another machine. Use 0 for scenes in tiny units.
DEFAULT_ATOL = 1e-12
