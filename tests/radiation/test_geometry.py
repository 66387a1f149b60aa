"""Furnace geometry: surface order and areas, orientation, moving parts, display meshes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import small_config
from twin.physics.geometry import (
    CONTACT_GAP,
    LAMP_SECTIONS,
    display_meshes,
    furnace_geometry,
    specimen_plate_mesh,
)


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def geo(cfg):
    return furnace_geometry(cfg, 0.0)


def test_surface_order_and_counts(cfg, geo):
    ns = cfg.specimen.n_states
    nw = 2 + cfg.housing.sections + 2
    assert (geo.n_specimen, geo.n_walls, geo.n_lamps) == (ns, nw, cfg.lamps.n_lamps)
    assert geo.n_surfaces == 2 * ns + nw + cfg.lamps.n_lamps
    assert geo.names[0] == "specimen_front_0" and geo.names[ns] == "specimen_back_0"
    assert geo.wall_names[:2] == ("reflector_h", "reflector_v")
    assert geo.wall_names[-2:] == ("holder_upper", "holder_lower")
    assert geo.names[2 * ns + nw] == "h1" and geo.names[-1] == f"v{cfg.lamps.vertical.count}"
    expected_t = [cfg.reflector.temperature] * 2 + [cfg.housing.temperature] * cfg.housing.sections
    expected_t += [cfg.holders.temperature_upper, cfg.holders.temperature_lower]
    np.testing.assert_array_equal(geo.wall_temperatures, expected_t)


def test_areas_match_the_drawing(cfg, geo):
    s, ns = cfg.specimen, cfg.specimen.n_states
    # every FD cell face is L_s W_s / N_s (paper section 2.1: equal rectangular elements)
    np.testing.assert_allclose(geo.area[: 2 * ns], s.length * s.width / ns, rtol=1e-12)
    # housing: both y faces (x-length L_x, z-height H) plus both x faces (W_y x H)
    (x0, x1), (y0, y1), (z0, z1) = cfg.housing_x_range, cfg.housing_y_range, cfg.housing_z_range
    housing = geo.area[2 * ns + 2 : 2 * ns + 2 + cfg.housing.sections].sum()
    assert housing == pytest.approx(2 * (x1 - x0) * (z1 - z0) + 2 * (y1 - y0) * (z1 - z0), rel=1e-12)
    assert geo.area[2 * ns] == pytest.approx((x1 - x0) * (y1 - y0), rel=1e-12)
    # lamps: regular n-gon prism, lateral n * 2 r sin(pi/n) * l plus two caps n/2 r^2 sin(2 pi/n)
    h = cfg.lamps.horizontal
    n, r = LAMP_SECTIONS, h.diameter / 2
    lamp = n * 2 * r * math.sin(math.pi / n) * h.heated_length + n * r * r * math.sin(2 * math.pi / n)
    assert geo.area[2 * ns + geo.n_walls] == pytest.approx(lamp, rel=1e-10)
    np.testing.assert_allclose(geo.lamp_nominal_area[0], math.pi * h.diameter * h.heated_length)


def test_optics_sum_to_one(geo):
    # eps + rho^s + rho^d = 1 for every surface (paper, after eq. 5)
    total = geo.emissivity + geo.specular_reflectivity + geo.diffuse_reflectivity
    np.testing.assert_allclose(total, 1.0, atol=1e-12)


def test_wall_normals_point_into_the_chamber(cfg, geo):
    enc = geo.enclosure
    centroid = enc.vertices[enc.faces].mean(axis=1)
    ns = cfg.specimen.n_states
    walls = (enc.face_surface >= 2 * ns) & (enc.face_surface < 2 * ns + 2 + cfg.housing.sections)
    centre = np.array([cfg.specimen.length / 2, cfg.specimen.width / 2, 0.0])
    assert np.all(np.einsum("ij,ij->i", centre - centroid[walls], enc.face_normals[walls]) > 0)
    front = enc.face_surface < ns
    back = (enc.face_surface >= ns) & (enc.face_surface < 2 * ns)
    assert np.all(enc.face_normals[front, 2] == pytest.approx(1.0))
    assert np.all(enc.face_normals[back, 2] == pytest.approx(-1.0))


def test_specimen_and_holders_move_with_eta(cfg):
    eta = 0.03
    g0, g1 = furnace_geometry(cfg, 0.0), furnace_geometry(cfg, eta)
    for g, e in ((g0, 0.0), (g1, eta)):
        enc = g.enclosure
        cell0 = enc.vertices[enc.faces[enc.face_surface == 0]].reshape(-1, 3)
        assert cell0[:, 0].min() == pytest.approx(e)
        assert cell0[:, 0].max() == pytest.approx(e + cfg.specimen.length / cfg.specimen.nx)
        up = g.names.index("holder_upper")
        jaw = enc.vertices[enc.faces[enc.face_surface == up]].reshape(-1, 3)
        h = cfg.holders
        assert jaw[:, 0].min() == pytest.approx(e - h.arm_length)
        assert jaw[:, 0].max() == pytest.approx(e + h.clamp_length)
        # contact face just above the specimen face (numerical clearance only)
        assert np.abs(jaw[:, 2]).min() == pytest.approx(cfg.specimen.thickness / 2 + CONTACT_GAP)
    # lamps and reflectors stay put
    lamps0 = g0.enclosure.vertices[g0.enclosure.faces[g0.enclosure.face_surface == g0.names.index("h1")]]
    lamps1 = g1.enclosure.vertices[g1.enclosure.faces[g1.enclosure.face_surface == g1.names.index("h1")]]
    np.testing.assert_array_equal(lamps0, lamps1)


def test_lamp_positions_follow_the_pitch(cfg, geo):
    enc, s = geo.enclosure, cfg.specimen
    h, v = cfg.lamps.horizontal, cfg.lamps.vertical
    for k in range(h.count):
        pts = enc.vertices[enc.faces[enc.face_surface == geo.names.index(f"h{k + 1}")]].reshape(-1, 3)
        assert pts[:, 0].mean() == pytest.approx(s.length / 2 + (k - (h.count - 1) / 2) * h.pitch, abs=1e-9)
        assert pts[:, 2].mean() == pytest.approx(h.distance, abs=1e-9)
    pts = enc.vertices[enc.faces[enc.face_surface == geo.names.index("v1")]].reshape(-1, 3)
    assert pts[:, 1].mean() == pytest.approx(s.width / 2 - (v.count - 1) / 2 * v.pitch, abs=1e-9)
    assert pts[:, 2].mean() == pytest.approx(-v.distance, abs=1e-9)


def test_display_meshes_and_plate(cfg):
    meshes = display_meshes(cfg, 0.02)
    kinds = {k for _, k, _, _ in meshes}
    assert kinds == {"specimen", "lamp", "reflector", "housing", "holder", "window"}
    for _, _, v, f in meshes:
        assert v.shape[1] == 3 and f.shape[1] == 3 and f.min() >= 0 and f.max() < len(v)
    v, f, cell = specimen_plate_mesh(cfg, 0.02)
    s = cfg.specimen
    assert v.shape == ((s.nx + 1) * (s.ny + 1), 3)
    np.testing.assert_array_equal(np.bincount(cell), np.full(s.n_states, 2))
    # the triangles of cell k = i + N_x j cover [x_i, x_i+1] x [y_j, y_j+1] shifted by eta
    k = 3 + s.nx * 5
    pts = v[f[cell == k]].reshape(-1, 3)
    dx, dy = s.length / s.nx, s.width / s.ny
    assert pts[:, 0].min() == pytest.approx(0.02 + 3 * dx) and pts[:, 1].max() == pytest.approx(6 * dy)
