"""Discontinuity mesh, element form factors and radiosity against independent oracles."""

import numpy as np
import pytest
from flatland_oracles import monte_carlo_elements
from flatland_scenes import occluded_scene, random_mixed

from viscx.flatland.complex import build
from viscx.flatland.mesh import discontinuity_mesh, element_form_factors, radiosity, solve_radiosity


@pytest.fixture(scope="module")
def occluded():
    cx = build(occluded_scene())
    mesh = discontinuity_mesh(cx)
    F = element_form_factors(cx, mesh)
    return cx, mesh, F


def _aggregate(cx, mesh, F):
    """Object form factors from element ones: L_i F_ij = Σ_e∈i L_e Σ_f∈j F_ef."""
    n = cx.scene.n
    k = np.append(mesh["elem_obj"], n)
    Le = mesh["elem_length"]
    G = np.zeros((n, n + 1))
    np.add.at(G, (np.repeat(mesh["elem_obj"], len(k)), np.tile(k, len(Le))), (Le[:, None] * F).ravel())
    return G / cx.scene.perimeters()[:, None]


def test_mesh_cuts_at_every_discontinuity(occluded):
    cx, mesh, F = occluded
    # every tangent point and every segment end on an object is an element boundary
    for k, s in zip(mesh["cut_obj"], mesh["cut_s"]):
        st = mesh["elem_s"][mesh["elem_obj"] == k, 0]
        L = cx.scene.perimeters()[k]
        assert np.min(np.abs((st - s + L / 2) % L - L / 2)) < 1e-9 * L
    # elements tile each boundary exactly once
    tot = np.bincount(mesh["elem_obj"], weights=mesh["elem_length"])
    assert np.allclose(tot, cx.scene.perimeters(), rtol=1e-13, atol=0)


def test_element_form_factors_consistent_with_complex(occluded):
    cx, mesh, F = occluded
    assert np.max(np.abs(F.sum(axis=1) - 1.0)) < 1e-9
    assert np.max(np.abs(_aggregate(cx, mesh, F) - cx.F_area)) < 1e-9
    Le = mesh["elem_length"]
    LF = Le[:, None] * F[:, :-1]
    assert np.max(np.abs(LF - LF.T)) < 1e-12


def test_element_form_factors_monte_carlo(occluded):
    """10⁶ random lines classified by the elements they leave and reach: within 4σ."""
    cx, mesh, F = occluded
    Fmc, sig = monte_carlo_elements(cx.scene, mesh["elem_obj"], mesh["elem_s"], n_lines=1_000_000, seed=3)
    z = np.abs(F - Fmc) / np.maximum(sig, 1e-12)
    # a pair that the exact method finds unreachable is never hit by a sampled line
    assert np.all(Fmc[F < 1e-15] == 0)
    assert np.all(z[sig > 0] < 4.0), np.sort(z[sig > 0])[-5:]


def test_radiosity_equals_dense_solve_and_energy_balance(occluded):
    cx, mesh, F = occluded
    k = mesh["elem_obj"]
    E, rho = cx.scene.emission[k], cx.scene.reflectance[k]
    Fe = F[:, :-1]
    B, it = solve_radiosity(Fe, E, rho)
    dense = np.linalg.solve(np.eye(len(B)) - rho[:, None] * Fe, E)
    assert np.max(np.abs(B - dense)) < 1e-10 * max(1.0, dense.max())
    # energy: emitted = absorbed + escaped to the sky; incident flux on e is Σ_f F_ef B_f
    Le = mesh["elem_length"]
    H = Fe @ B
    emitted = np.sum(E * Le)
    absorbed = np.sum((1 - rho) * H * Le)
    escaped = np.sum(B * Le * F[:, -1])
    assert abs(emitted - absorbed - escaped) < 1e-9 * emitted
    assert np.all(B >= E - 1e-15)


def test_radiosity_pipeline_random_scene():
    cx = build(random_mixed(8, seed=11, density=3.0))
    out = radiosity(cx)
    assert np.max(np.abs(out["elem_F"].sum(axis=1) - 1.0)) < 1e-9
    assert np.max(np.abs(_aggregate(cx, out, out["elem_F"]) - cx.F_area)) < 1e-9


@pytest.fixture(scope="module")
def row_over_ground():
    """One panel (a segment) above a ground block, and a square column: a face leaving the
    ground to the sky is two u-intervals at one θ (either side of the panel's shadow)."""
    from flatland_scenes import panel_rows

    from viscx.flatland.scene import make_scene

    sc = panel_rows(1, thick=0)
    objs = sc.to_json()["objects"] + [{"type": "polygon", "points": [[4, 2], [5, 2], [5, 3], [4, 3]], "name": "col"}]
    cx = build(make_scene(objs))
    return cx, radiosity(cx, sky_radiance=1.0)


def test_element_rows_and_sky_column_exact(row_over_ground):
    """Every element's row sums to 1 with the sky, and each element-to-object sum and the
    sky column equal the exact integration (edge-piece oracle) to 1e-9."""
    from flatland_oracles import exact_F_part
    from flatland_scenes import corners_of

    cx, m = row_over_ground
    F = m["elem_F"]
    assert np.max(np.abs(F.sum(axis=1) - 1.0)) < 1e-9
    objs = corners_of(cx.scene)
    n = cx.scene.n
    G = np.zeros((len(F), n))
    np.add.at(G.T, m["elem_obj"], F[:, :-1].T)
    from viscx.flatland.mesh import point_at

    for e in range(len(F)):
        k = int(m["elem_obj"][e])
        p0, p1 = point_at(cx.scene, k, np.array([m["elem_s"][e, 0], m["elem_s"][e, 1] - 1e-300]))
        # the exact end of the element: its arc end (point_at wraps at the perimeter)
        p1 = point_at(cx.scene, k, np.array([m["elem_s"][e, 1]]))[0] if m["elem_s"][e, 1] < cx.scene.perimeters()[k] \
            else objs[k][0]
        want = np.array([exact_F_part(objs, k, j, p0, p1) if j != k else 0.0 for j in range(n)])
        assert np.max(np.abs(G[e] - want)) < 1e-9, (e, G[e], want)
        assert abs(F[e, -1] - (1.0 - want.sum())) < 1e-9


def test_sky_radiance_irradiance(row_over_ground):
    """B = E + ρ (F B + F_sky L_sky) against a dense solve; irradiance H = F B + F_sky L;
    with ρ = 0 the irradiance is exactly the sky view factor; a segment's two sides are
    its edges 0 and 1."""
    cx, m = row_over_ground
    F = m["elem_F"]
    rho, E = m["elem_reflectance"], m["elem_emission"]
    dense = np.linalg.solve(np.eye(len(rho)) - rho[:, None] * F[:, :-1], E + rho * F[:, -1])
    assert np.max(np.abs(m["elem_B"] - dense)) < 1e-10
    assert np.max(np.abs(m["elem_H"] - (F[:, :-1] @ dense + F[:, -1]))) < 1e-10
    panel = m["elem_obj"] == 0
    assert set(m["elem_edge"][panel]) == {0, 1}
    # the panel's upper (left of p0 → p1) side sees more sky than its lower side
    Le = m["elem_length"]
    up = np.sum((Le * m["elem_H"])[panel & (m["elem_edge"] == 1)])
    down = np.sum((Le * m["elem_H"])[panel & (m["elem_edge"] == 0)])
    assert up > down
    black = radiosity(cx.__class__(scene=_black(cx.scene), eps=cx.eps, arrays=cx.arrays), sky_radiance=2.0)
    assert np.max(np.abs(black["elem_H"] - 2.0 * black["elem_F"][:, -1])) < 1e-12


def _black(scene):
    from dataclasses import replace

    return replace(scene, reflectance=np.zeros(scene.n))
