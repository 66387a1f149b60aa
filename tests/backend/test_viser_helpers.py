"""Pure helpers of the 3D view: vertex values, colour range, lamp colours."""

from __future__ import annotations

import numpy as np

from backend.viser import LAMP_OFF, LAMP_ON, MIN_SPAN_K, colour_range, lamp_colors, plate_mesh, turbo_rgb
from twin.physics.geometry import specimen_plate_mesh


def test_vertex_values_of_a_linear_field_are_exact_inside(small_cfg) -> None:
    from backend.viser import vertex_values

    s = small_cfg.specimen
    x = (np.arange(s.nx) + 0.5) / s.nx * s.length
    y = (np.arange(s.ny) + 0.5) / s.ny * s.width
    field = 700.0 + 900.0 * x[None, :] + 300.0 * y[:, None]  # (N_y, N_x), linear in x and y
    v = vertex_values(field).reshape(s.ny + 1, s.nx + 1)
    verts, _, _ = specimen_plate_mesh(small_cfg, 0.0)
    vx = verts[:, 0].reshape(s.ny + 1, s.nx + 1)
    vy = verts[:, 1].reshape(s.ny + 1, s.nx + 1)
    exact = 700.0 + 900.0 * vx + 300.0 * vy
    # the mean of the four cells around an interior vertex of a linear field is its value there
    np.testing.assert_allclose(v[1:-1, 1:-1], exact[1:-1, 1:-1], rtol=0, atol=1e-9)


def test_colour_range_is_stable_and_wide_enough() -> None:
    f = np.array([[1093.2, 1097.9], [1101.4, np.nan]])
    assert colour_range(f) == (1090.0, 1105.0)  # min/max widened to multiples of 5 K
    lo, hi = colour_range(np.full((3, 3), 1100.0))
    assert hi - lo == MIN_SPAN_K
    assert colour_range(np.full((2, 2), np.nan)) == (290.0, 310.0)


def test_turbo_ends_and_plate_mesh(small_cfg) -> None:
    rgb = turbo_rgb(np.array([0.0, 300.0, 1e6]), 300.0, 1300.0)
    assert rgb.dtype == np.uint8 and tuple(rgb[0]) == tuple(rgb[1])  # clipped below the range
    s = small_cfg.specimen
    colours = np.zeros(((s.nx + 1) * (s.ny + 1), 3), np.uint8)
    mesh = plate_mesh(small_cfg, colours)
    assert len(mesh.vertices) == 2 * (s.nx + 1) * (s.ny + 1)  # front and back face
    assert len(mesh.faces) == 4 * s.nx * s.ny


def test_lamp_colours_follow_their_group(small_cfg) -> None:
    u = np.array([1.0, 0.0, 0.5, 0.0, 0.0, 0.25])
    rgb = lamp_colors(small_cfg, u).astype(float)
    G = small_cfg.group_matrix
    for k in range(G.shape[0]):
        frac = float(G[k] @ u)  # each lamp is in at most one group
        np.testing.assert_allclose(rgb[k], np.floor(LAMP_OFF + frac * (LAMP_ON - LAMP_OFF)), atol=1.0)
    ungrouped = np.where(G.sum(axis=1) == 0)[0]
    assert len(ungrouped) > 0 and all(tuple(rgb[k]) == tuple(LAMP_OFF) for k in ungrouped)


def test_scene_runs_like_the_heat_map_and_names_its_parts(small_cfg) -> None:
    """The camera looks at the +z face with y up, so x (the length) runs left to right as on the dashboard's
    heat map; the lamp groups, reflectors, holders and window carry labels."""
    import viser

    from backend.viser import FurnaceScene

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        scene = FurnaceScene(server, small_cfg)
        cam = server.initial_camera
        eye, target, up = np.asarray(cam.position), np.asarray(cam.look_at), np.asarray(cam.up)
        forward = (target - eye) / np.linalg.norm(target - eye)
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        screen_up = np.cross(right, forward)
        assert right @ np.array([1.0, 0.0, 0.0]) > 0.99  # +x to the right on screen
        assert screen_up @ np.array([0.0, 1.0, 0.0]) > 0.7  # +y up on screen (seen a little from below)
        labels = {h.text for h in scene.labels.values()}
        for g in small_cfg.lamps.groups:
            assert g.name in labels, g.name
        for part in ("gold reflector (horizontal lamps)", "gold reflector (vertical lamps)", "upper holder (x = 0)",
                     "lower holder", "quartz window"):
            assert part in labels, part
    finally:
        server.stop()


def test_scene_colours_the_plate_by_sigma_when_asked(small_cfg) -> None:
    """With "Colour by sigma" the plate shows field_sigma (Blues from 0 K: a larger sigma is darker), and the
    field's turbo colours otherwise or when the snapshot has no sigma."""
    from dataclasses import replace

    import viser

    from backend.viser import FurnaceScene
    from twin.runs.record import Snapshot

    s = small_cfg.specimen
    sigma = np.tile(np.linspace(0.5, 8.0, s.nx), (s.ny, 1))  # grows along x
    snap = Snapshot(j=0, t=0.0, eta=0.0, T_ref=900.0, T_mean_hat=900.0, field_hat=np.full((s.ny, s.nx), 900.0),
                    field_true=None, tc=np.full(4, 900.0), tc_hat=np.full(4, 900.0), u=np.zeros(6), u_ff=np.zeros(6),
                    inhomogeneity=0.0, true_mean=None, true_inhomogeneity=None, field_sigma=sigma)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        scene = FurnaceScene(server, small_cfg)
        lo, hi = scene.show(snap, small_cfg.tc_positions(), sigma=True)
        assert (lo, hi) == (0.0, 8.0)
        rgb = scene.plate_rgb.astype(float).reshape(s.ny + 1, s.nx + 1, 3)
        assert rgb[:, -1].sum() < rgb[:, 0].sum()  # darker where sigma is larger
        flat = scene.plate_rgb.copy()
        scene.show(snap, small_cfg.tc_positions(), sigma=False)  # a uniform field: one colour
        assert not np.array_equal(flat, scene.plate_rgb) and len(np.unique(scene.plate_rgb, axis=0)) == 1
        scene.show(replace(snap, field_sigma=None), small_cfg.tc_positions(), sigma=True)
        assert len(np.unique(scene.plate_rgb, axis=0)) == 1
    finally:
        server.stop()


def test_lamp_group_labels_never_sit_side_by_side_at_the_same_end(small_cfg) -> None:
    """Issue 27 item 10: "T3hT1h".  Two group labels at the same end of the lamps closer across the array than a
    label's width (5 cm: "T3h" is about 3 cm at the default zoom) must be staggered along the lamps by 2 cm or more.
    The old placement (ends alternating by group number) put T3h and T1h 2.4 cm apart on one line."""
    from backend.viser.scene import group_label_places
    from twin.physics.geometry import display_meshes

    boxes = {n: (v.min(axis=0), v.max(axis=0)) for n, _, v, _ in display_meshes(small_cfg, 0.0)}
    places = group_label_places(small_cfg, boxes)
    assert {text for _, text, _, _ in places} == {g.name for g in small_cfg.lamps.groups}  # every group named
    for side, across, along in (("h", 0, 1), ("v", 1, 0)):
        mine = [(pos, anchor) for node, _, pos, anchor in places if node.rsplit("-", 1)[1].startswith(side)]
        assert len(mine) >= 2
        for i, (p, a) in enumerate(mine):
            for q, b in mine[i + 1:]:
                if a == b and abs(p[across] - q[across]) < 0.05:
                    assert abs(p[along] - q[along]) >= 0.02, (side, p, q)
