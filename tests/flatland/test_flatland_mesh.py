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
