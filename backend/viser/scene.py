"""The furnace on the 3D scene: plate, lamps, reflectors, holders, window, housing and TC markers.

The specimen plate is coloured per vertex by the estimated field and moves with eta between
the two lamp arrays; each lamp is coloured by its group's power (dark = off, bright yellow =
u_max); the gold reflectors, the holders (moving with the plate), the quartz window and,
optionally, the housing are drawn from ``twin.physics.geometry.display_meshes``.  TC markers
show their readings; labels name the lamp groups (at each grouped lamp's end), the reflectors,
the holders and the window.  The camera looks at the horizontal-lamp (+z) face with y up, so the
specimen's length x runs left to right as on the dashboard's heat map (x = 0, the upper holder in
the real furnace, on the left).  :meth:`FurnaceScene.show` puts one snapshot on the scene in one
``server.atomic()`` block.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import trimesh
import viser

from backend.streaming.frames import SnapshotLike
from twin.config import FurnaceConfig
from twin.physics.geometry import display_meshes, specimen_plate_mesh

GOLD = (212, 175, 55)
LAMP_OFF = np.array([70, 70, 78], dtype=float)
LAMP_ON = np.array([255, 236, 80], dtype=float)
MIN_SPAN_K = 10.0  # colour range of the plate spans at least this many kelvin
#: shadows cost a lot in software WebGL (headless browsers, remote desktops) and add nothing here
NO_SHADOW: dict[str, Any] = {"cast_shadow": False, "receive_shadow": False}
Anchor = Literal["top-center", "bottom-center", "center-left", "center-right", "bottom-right"]


def turbo_rgb(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Temperatures (K) -> uint8 RGB with matplotlib's turbo map over [lo, hi]."""
    from matplotlib import colormaps

    x = np.clip((np.asarray(values, dtype=float) - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    return (colormaps["turbo"](x)[..., :3] * 255).astype(np.uint8)


def sigma_rgb(values: np.ndarray, hi: float) -> np.ndarray:
    """Standard deviations (K) -> uint8 RGB with matplotlib's Blues over [0, hi] (not to be read as temperature)."""
    from matplotlib import colormaps

    x = np.clip(np.asarray(values, dtype=float) / max(hi, 1e-9), 0.0, 1.0)
    return (colormaps["Blues"](0.1 + 0.9 * x)[..., :3] * 255).astype(np.uint8)


def colour_range(field: np.ndarray, step: float = 5.0) -> tuple[float, float]:
    """Colour range (K) of the plate: its min..max widened to multiples of ``step`` and to at
    least ``MIN_SPAN_K``, so the colours do not flicker with the noise of the estimate."""
    f = np.asarray(field, dtype=float)
    finite = f[np.isfinite(f)]
    if not finite.size:
        return (290.0, 310.0)
    lo, hi = step * np.floor(finite.min() / step), step * np.ceil(finite.max() / step)
    if hi - lo < MIN_SPAN_K:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - MIN_SPAN_K / 2, mid + MIN_SPAN_K / 2
    return (float(lo), float(hi))


def vertex_values(field: np.ndarray) -> np.ndarray:
    """Cell-centred field (N_y, N_x) -> vertex values ((N_y+1) (N_x+1),) by averaging the
    (up to four) cells around each vertex; vertex (i, j) at index i + (N_x + 1) j."""
    f = np.asarray(field, dtype=float)
    p = np.pad(f, 1, mode="edge")
    v = 0.25 * (p[:-1, :-1] + p[1:, :-1] + p[:-1, 1:] + p[1:, 1:])
    return v.ravel()


def plate_mesh(cfg: FurnaceConfig, colors: np.ndarray) -> trimesh.Trimesh:
    """Both faces of the specimen at eta = 0 with per-vertex colours ((N_x+1)(N_y+1), 3) uint8."""
    verts, faces, _ = specimen_plate_mesh(cfg, 0.0)
    back = verts.copy()
    back[:, 2] = -back[:, 2]
    n = len(verts)
    return trimesh.Trimesh(
        vertices=np.vstack([verts, back]),
        faces=np.vstack([faces, faces[:, ::-1] + n]),
        vertex_colors=np.vstack([colors, colors]),
        process=False,
    )


def lamp_colors(cfg: FurnaceConfig, u: np.ndarray) -> np.ndarray:
    """(N_lamps, 3) uint8: each lamp coloured by the power fraction of its group (0 if none)."""
    frac = np.clip(cfg.group_matrix @ np.nan_to_num(np.asarray(u, dtype=float)), 0.0, 1.0)
    return (LAMP_OFF + frac[:, None] * (LAMP_ON - LAMP_OFF)).astype(np.uint8)


#: group labels two blocks apart share an end of the lamps: every other pair of them sits this much further out (m)
LABEL_STAGGER = 0.03


def group_label_places(cfg: FurnaceConfig, boxes: dict[str, tuple[np.ndarray, np.ndarray]]
                       ) -> list[tuple[str, str, tuple[float, float, float], Anchor]]:
    """Where each lamp group's name goes: once per block of neighbouring lamps of a group, at an end of the
    lamps (horizontal lamps: top or bottom, vertical lamps: left or right).  The blocks alternate ends in their
    order along the array, so neighbours are at opposite ends, and the labels two blocks apart (the same end)
    are staggered by :data:`LABEL_STAGGER`: groups alternating by group number put T1h and T3h side by side
    ("T3hT1h").  ``boxes``: each lamp mesh's (min, max) corner.  Returns (node, text, position, anchor)."""
    blocks: dict[str, list[tuple[np.ndarray, np.ndarray, str, int]]] = {"h": [], "v": []}
    for g in cfg.lamps.groups:
        numbers: dict[str, list[int]] = {}
        for lamp in g.lamps:
            side, k = lamp[0], int(lamp[1:])
            count = cfg.lamps.horizontal.count if side == "h" else cfg.lamps.vertical.count
            numbers.setdefault(side, []).append(k if k > 0 else count + 1 + k)
        for side, ks in numbers.items():
            runs: list[list[int]] = []
            for k in sorted(ks):  # neighbouring lamps form one block, labelled once
                if runs and k == runs[-1][-1] + 1:
                    runs[-1].append(k)
                else:
                    runs.append([k])
            for bi, run in enumerate(runs):
                lo = np.min([boxes[f"{side}{k}"][0] for k in run], axis=0)
                hi = np.max([boxes[f"{side}{k}"][1] for k in run], axis=0)
                blocks[side].append((lo, hi, g.name, bi))
    out: list[tuple[str, str, tuple[float, float, float], Anchor]] = []
    for side, found in blocks.items():
        across = 0 if side == "h" else 1  # horizontal lamps lie along y, side by side in x; vertical ones along x
        found.sort(key=lambda b: float(b[0][across] + b[1][across]))
        for rank, (lo, hi, name, bi) in enumerate(found):
            first, out_by = rank % 2 == 0, LABEL_STAGGER * ((rank // 2) % 2)
            anchor: Anchor
            if side == "h":  # at the top (+y) or bottom end
                pos = (0.5 * float(lo[0] + hi[0]), float(hi[1]) + out_by if first else float(lo[1]) - out_by,
                       float(hi[2]))
                anchor = "bottom-center" if first else "top-center"
            else:  # at the left or right end
                pos = (float(lo[0]) - out_by if first else float(hi[0]) + out_by, 0.5 * float(lo[1] + hi[1]),
                       float(lo[2]))
                anchor = "center-right" if first else "center-left"
            out.append((f"/labels/groups/{name}-{side}{bi}", name, pos, anchor))
    return out


class FurnaceScene:
    """The scene's handles; :meth:`show` redraws only what a snapshot changed."""

    def __init__(self, server: viser.ViserServer, cfg: FurnaceConfig) -> None:
        self.server = server
        self.cfg = cfg
        self.lamps: list[Any] = []
        self.holders: list[Any] = []
        self.housing: list[Any] = []
        self.tc_markers: list[Any] = []
        self.tc_labels: list[Any] = []
        self.labels: dict[str, Any] = {}  # the names of the parts on the scene (scene node -> label handle)
        self.plate_rgb: np.ndarray | None = None  # vertex colours on the plate now
        self._lamp_rgb: np.ndarray | None = None
        self._build()

    def _build(self) -> None:
        sc, s = self.server.scene, self.cfg.specimen
        # the heat map's orientation: x (the length) to the right, y (the width) up, seen from +z
        sc.set_up_direction("+y")
        self.server.initial_camera.position = (s.length / 2, s.width / 2 - 0.38, 0.52)  # a little from below
        self.server.initial_camera.look_at = (s.length / 2, s.width / 2, 0.0)
        self.server.initial_camera.up = (0.0, 1.0, 0.0)
        meshes = display_meshes(self.cfg, 0.0)
        self._add_labels(meshes)
        for name, kind, verts, faces in meshes:
            if kind == "lamp":
                self.lamps.append(sc.add_mesh_simple(f"/furnace/lamps/{name}", verts, faces, color=tuple(LAMP_OFF),
                                                     **NO_SHADOW))
            elif kind == "reflector":  # the one between the camera (+z) and the plate only a faint tint
                near = float(np.mean(verts[:, 2])) > 0
                sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=GOLD, opacity=0.05 if near else 0.18,
                                   side="double", **NO_SHADOW)
            elif kind == "holder":
                self.holders.append(sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=(110, 120, 135),
                                                       **NO_SHADOW))
            elif kind == "window":
                sc.add_mesh_simple(f"/furnace/{name}", verts, faces, color=(170, 210, 240), opacity=0.15,
                                   side="double", **NO_SHADOW)
            elif kind == "housing":
                self.housing.append(sc.add_mesh_simple(f"/furnace/housing/{name}", verts, faces,
                                                       color=(150, 155, 165), opacity=0.12, side="double",
                                                       visible=False, **NO_SHADOW))
        field = np.full((s.ny, s.nx), s.initial_temperature)
        cold = turbo_rgb(vertex_values(field), 290.0, 310.0)
        self.plate = sc.add_mesh_trimesh("/furnace/specimen", plate_mesh(self.cfg, cold), **NO_SHADOW)
        for k, (x, y) in enumerate(self.cfg.tc_positions()):
            color = (255, 80, 200) if k == 3 else (255, 255, 255)
            self.tc_markers.append(sc.add_icosphere(f"/furnace/tc/TC{k + 1}", radius=0.004, color=color,
                                                    position=(x, y, 0.0), **NO_SHADOW))  # pokes out of both faces
            self.tc_labels.append(sc.add_label(f"/furnace/tc/TC{k + 1}/label", f"TC{k + 1}",
                                               position=(0.0, 0.0, 0.0),
                                               anchor="bottom-left" if k == 1 else "top-left"))

    def _add_labels(self, meshes: list[tuple[str, str, np.ndarray, np.ndarray]]) -> None:
        """Names on the scene: each lamp group once per block of neighbouring lamps (:func:`group_label_places`),
        the reflectors, the holders and the window."""
        sc = self.server.scene
        boxes = {name: (verts.min(axis=0), verts.max(axis=0)) for name, _, verts, _ in meshes}
        for node, text, pos, anchor in group_label_places(self.cfg, boxes):
            self.labels[node] = sc.add_label(node, text, position=pos, anchor=anchor)
        words = {"reflector_h": "gold reflector (horizontal lamps)", "reflector_v": "gold reflector (vertical lamps)",
                 "holder_upper": "upper holder (x = 0)", "holder_lower": "lower holder", "window": "quartz window"}
        for name, text in words.items():
            if name not in boxes:
                continue
            lo, hi = boxes[name]
            where: Anchor
            if name.startswith("reflector"):
                pos, where = (hi[0], hi[1], hi[2]), "bottom-right"
            else:
                pos, where = (0.5 * (lo[0] + hi[0]), lo[1], hi[2]), "top-center"
            self.labels[f"/labels/{name}"] = sc.add_label(f"/labels/{name}", text, position=pos, anchor=where)

    def show_housing(self, visible: bool) -> None:
        with self.server.atomic():
            for h in self.housing:
                h.visible = visible

    def show(self, snap: SnapshotLike, tc_positions: Sequence[tuple[float, float]],
             sigma: bool = False) -> tuple[float, float]:
        """Put one snapshot on the scene (plate colours and position, lamps, TCs at ``tc_positions``
        in m at eta = 0); returns the plate's colour range (K).  ``sigma``: the plate shows the estimate's
        standard deviation (``field_sigma``, Blues from 0 K) instead of the field, when the snapshot has it."""
        field_sigma = getattr(snap, "field_sigma", None)
        eta = float(snap.eta)
        if sigma and field_sigma is not None:
            values = vertex_values(np.asarray(field_sigma, dtype=float))
            lo, hi = 0.0, float(np.ceil(np.nanmax(values))) if np.isfinite(values).any() else 1.0
            colours = sigma_rgb(values, hi)
        else:
            field = np.asarray(snap.field_hat, dtype=float)
            lo, hi = colour_range(field)
            colours = turbo_rgb(vertex_values(field), lo, hi)
        rgb = lamp_colors(self.cfg, np.asarray(snap.u))
        with self.server.atomic():
            if self.plate_rgb is None or not np.array_equal(colours, self.plate_rgb):
                # a new GLB only when a vertex colour changed (each one costs the browser a parse)
                self.plate = self.server.scene.add_mesh_trimesh(
                    "/furnace/specimen", plate_mesh(self.cfg, colours), position=(eta, 0.0, 0.0), **NO_SHADOW)
                self.plate_rgb = colours
            else:
                self.plate.position = (eta, 0.0, 0.0)
            for h in self.holders:
                h.position = (eta, 0.0, 0.0)
            for k, handle in enumerate(self.lamps):
                if self._lamp_rgb is None or not np.array_equal(rgb[k], self._lamp_rgb[k]):
                    handle.color = tuple(int(c) for c in rgb[k])
            self._lamp_rgb = rgb
            for k, (x, y) in enumerate(tc_positions):
                self.tc_markers[k].position = (x + eta, y, 0.0)
                reading = float(np.asarray(snap.tc)[k])
                self.tc_labels[k].text = f"TC{k + 1} {reading:.1f} K" if np.isfinite(reading) else f"TC{k + 1} –"
        return lo, hi
