"""Epsilon-merging of nodes (viscx.skeleton.sites): nodes whose maximal free segments
coincide within epsilon are one site."""

import numpy as np
from conftest import ROOT, SAMPLES
from test_nodes import line_point_distance, point_segment_distance

from viscx.formats.hdf5 import ViscxFile, read_nodes
from viscx.scene import load_scene
from viscx.skeleton.candidates import build_nodes
from viscx.skeleton.nodes import E4, VEE, VV, Nodes
from viscx.skeleton.reference import reference_nodes
from viscx.skeleton.sites import node_sites


def fake_nodes(ends):
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 2, 3)
    n = len(ends)
    d = ends[:, 1] - ends[:, 0]
    return Nodes(kind=np.full(n, VV, np.int8), generators=np.zeros((n, 4), np.int64),
                 direction=d / np.linalg.norm(d, axis=1, keepdims=True), ends=ends,
                 blocker_kind=np.zeros((n, 2), np.int8), blocker=np.zeros((n, 2), np.int64),
                 generator_points=np.full((n, 4, 3), np.nan))


def test_sites_by_hand():
    eps = 1e-3
    base = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    shift = np.array([0.0, 1.0, 0.0])
    ends = [base, base + 0.6 * eps * shift, base + 1.2 * eps * shift,  # a chain: one site
            base + 5 * eps * shift,                                     # alone
            base + np.array([[0, 0, 0], [0, 2 * eps, 0]])]              # one end within eps only
    assert node_sites(fake_nodes(ends), eps).tolist() == [0, 0, 0, 3, 4]
    assert node_sites(fake_nodes(ends[:0]), eps).tolist() == []


def test_room_with_door_t_junctions_are_merged():
    """room_with_door: a vertex of the inner wall lies on the room's edges (T-junctions), so
    VEE and E4 nodes describe one segment; each site's segment passes within epsilon of
    every generator of every member (an independent check of the grouping), and the
    fast builder and the reference give the same sites."""
    scene = load_scene(SAMPLES / "room_with_door.obj")
    nodes = build_nodes(scene)
    sites = node_sites(nodes, scene.epsilon)
    merged = np.flatnonzero(sites != np.arange(len(sites)))
    assert len(merged) == 24 and len(np.unique(sites)) == len(nodes) - 24
    rep = sites[merged]
    o, d = nodes.ends[rep, 0], nodes.direction[rep]
    for slot in range(4):
        k, g = nodes.kind[merged], nodes.generators[merged, slot]
        vert = ((k == VV) & (slot < 2)) | ((k == VEE) & (slot == 0))
        assert np.all(line_point_distance(o[vert], d[vert], scene.vertices[g[vert]]) <= scene.epsilon)
        edge = ((k == VEE) & (slot in (1, 2))) | (k == E4)
        gp = nodes.generator_points[merged[edge], slot]
        ev = scene.half_edges.edge_vertices[g[edge]]
        assert np.all(point_segment_distance(gp, scene.vertices[ev[:, 0]], scene.vertices[ev[:, 1]]) <= scene.epsilon)
        assert np.all(line_point_distance(o[edge], d[edge], gp) <= scene.epsilon)
    assert np.array_equal(node_sites(reference_nodes(scene), scene.epsilon), sites)


def test_info_reports_sites():
    from viscx.cli.info import file_summary

    summary = file_summary(ROOT / "tests" / "golden" / "room_with_door.h5")
    assert summary["counts"]["V0"]["sites"] == summary["counts"]["V0"]["total"] - 24
    with ViscxFile(ROOT / "tests" / "golden" / "cornell_box.h5") as f:
        nodes = read_nodes(f.h5["V0"])
        eps = f.read_scene().epsilon
    assert len(np.unique(node_sites(nodes, eps))) == len(nodes)  # no coincident nodes there
