"""The furnace's radiating surfaces at a specimen position eta (paper section 2.1, Fig. 1).

The enclosure seen by the net-radiation method (eqs. 4-5) is a closed set of
triangulated surfaces.  Frame (header of ``default_furnace.toml``): x along the
specimen length (downwards), y across, z normal to the plate.  At position eta the
specimen occupies ``eta <= x <= eta + L_s``, ``0 <= y <= W_s``, faces at ``z = +-B_s/2``.

Surfaces, in the order of ``docs/interfaces.md``:

1. specimen front cells (+z face), k = i + N_x j (``N_s`` of them);
2. specimen back cells (-z face), same k;
3. "walls" (known temperature): the reflector behind the horizontal lamps (+z), the
   reflector behind the vertical lamps (-z), the housing sections, the upper and the
   lower holder;
4. lamps h_1..h_Nh, v_1..v_Nv (closed cylinders, known net flux).

Housing sections: the chamber's side walls (the faces y = const, spanning the full
z range between the two reflector planes) are cut into ``housing.sections`` equal
bands along x; the top face (x = x_min) belongs to the first band, the bottom face
(x = x_max) to the last.  Each section holds both y faces of its band, so the
sections are mirror symmetric about y = W_s/2.  Reflectors close the box at
``z = +-(distance + gap)``; the enclosure is closed.

Holders: each holder is two jaws (boxes of ``jaw_thickness``) clamping
``clamp_length`` of the specimen end on both faces, wider than the specimen by
``jaw_overhang`` on each side and reaching ``arm_length`` beyond the specimen end.
They move with eta.  A jaw's contact face lies ``CONTACT_GAP`` above the specimen
face (a numerical clearance, not a physical gap), so the clamped cells exchange
radiation with the jaw (view factor ~1) and rays leaving them cannot start inside
the jaw.

The quartz window is IR-transparent: it is returned by :func:`display_meshes` only.

Example
-------
>>> from twin.config import small_config
>>> cfg = small_config()
>>> g = furnace_geometry(cfg, 0.0)   # specimen front and back cells, walls, lamps
>>> g.n_surfaces == 2 * cfg.specimen.n_states + len(g.wall_names) + cfg.lamps.n_lamps
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: numerical clearance between a jaw's contact face and the specimen face (m); it only
#: has to exceed the ray-origin offset of the tracer (1e-6 m) and float32 round-off.
CONTACT_GAP = 1.0e-5
#: facets of a lamp cylinder; the faceted lateral area is sin(pi/n)/(pi/n) = 99.7 % of pi d l
LAMP_SECTIONS = 32


@dataclass(frozen=True, eq=False)
class Enclosure:
    """Triangulated surfaces for the ray tracer.

    Attributes
    ----------
    vertices : (V, 3) float, m
    faces : (M, 3) int, wound so that the right-hand normal points to the emitting side
    face_surface : (M,) int, surface index of each triangle
    face_normals : (M, 3) float, unit normals on the emitting side
    face_areas : (M,) float, m^2
    area : (n,) float, surface areas A_i (m^2)
    specular_reflectivity : (n,) float, rho^s_i
    """

    vertices: Array
    faces: IntArray
    face_surface: IntArray
    face_normals: Array
    face_areas: Array
    area: Array
    specular_reflectivity: Array

    @property
    def n_surfaces(self) -> int:
        return int(self.area.shape[0])


def rectangle(corner: Array, edge_u: Array, edge_v: Array) -> tuple[Array, IntArray]:
    """Two triangles of the parallelogram corner + [0,1] edge_u + [0,1] edge_v.

    The emitting side is ``edge_u x edge_v``.  Returns vertices (4, 3), faces (2, 3).
    """
    c, u, v = (np.asarray(a, float) for a in (corner, edge_u, edge_v))
    verts = np.array([c, c + u, c + u + v, c + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


def box(lo: Array, hi: Array) -> tuple[Array, IntArray]:
    """Closed axis-aligned box [lo, hi] with outward-facing triangles (8 vertices, 12 faces)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    verts = np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
        float,
    )
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces, dtype=np.int64)


def cylinder(start: Array, end: Array, radius: float, sections: int = LAMP_SECTIONS) -> tuple[Array, IntArray]:
    """Closed faceted cylinder from ``start`` to ``end`` with outward-facing triangles."""
    p0, p1 = np.asarray(start, float), np.asarray(end, float)
    axis = (p1 - p0) / np.linalg.norm(p1 - p0)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = 2 * np.pi * np.arange(sections) / sections
    ring = radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    verts = np.vstack([p0 + ring, p1 + ring, p0, p1])
    n = sections
    c0, c1 = 2 * n, 2 * n + 1
    faces = []
    for k in range(n):
        a, b = k, (k + 1) % n
        faces += [[a, b, n + b], [a, n + b, n + a]]  # lateral, outward (e1 x e2 = axis)
        faces += [[c0, b, a], [c1, n + a, n + b]]  # caps: -axis at start, +axis at end
    return verts, np.array(faces, dtype=np.int64)


def build_enclosure(
    parts: list[tuple[int, Array, IntArray]], specular_reflectivity: Array
) -> Enclosure:
    """Assemble ``(surface index, vertices, faces)`` parts into one :class:`Enclosure`."""
    verts, faces, owner = [], [], []
    offset = 0
    for surf, v, f in parts:
        verts.append(np.asarray(v, float))
        faces.append(np.asarray(f, np.int64) + offset)
        owner.append(np.full(len(f), surf, np.int64))
        offset += len(v)
    V = np.vstack(verts)
    Fc = np.vstack(faces)
    cross = np.cross(V[Fc[:, 1]] - V[Fc[:, 0]], V[Fc[:, 2]] - V[Fc[:, 0]])
    dbl = np.linalg.norm(cross, axis=1)
    rho_s = np.asarray(specular_reflectivity, float)
    face_surface = np.concatenate(owner)
    area = np.asarray(np.bincount(face_surface, weights=dbl / 2, minlength=len(rho_s)), float)
    if np.any(area <= 0):
        raise ValueError(f"surfaces without area: {np.flatnonzero(area <= 0).tolist()}")
    return Enclosure(V, Fc, face_surface, cross / dbl[:, None], dbl / 2, area, rho_s)


@dataclass(frozen=True, eq=False)
class FurnaceGeometry:
    """The furnace's radiating surfaces at one specimen position eta.

    Attributes
    ----------
    eta : float, m
    enclosure : :class:`Enclosure` for the ray tracer
    names : surface names, in the order of ``docs/interfaces.md``
    n_specimen, n_walls, n_lamps : N_s, N_w, N_lamps
    emissivity, specular_reflectivity, diffuse_reflectivity : (n,) optical properties
    wall_names : names of the known-temperature surfaces
    wall_temperatures : (N_w,) K
    lamp_nominal_area : (N_lamps,) pi d l (m^2), the area u is referred to (paper, after eq. 2)
    """

    eta: float
    enclosure: Enclosure
    names: tuple[str, ...]
    n_specimen: int
    n_walls: int
    n_lamps: int
    emissivity: Array
    specular_reflectivity: Array
    diffuse_reflectivity: Array
    wall_names: tuple[str, ...]
    wall_temperatures: Array
    lamp_nominal_area: Array

    @property
    def n_surfaces(self) -> int:
        return self.enclosure.n_surfaces

    @property
    def area(self) -> Array:
        return self.enclosure.area


def lamp_axes(cfg: FurnaceConfig) -> list[tuple[str, Array, Array, float]]:
    """(name, start, end, radius) of each lamp axis, order h_1..h_Nh, v_1..v_Nv (m)."""
    s, h, v = cfg.specimen, cfg.lamps.horizontal, cfg.lamps.vertical
    out = []
    for i in range(h.count):
        x = s.length / 2 + (i - (h.count - 1) / 2) * h.pitch
        y0, y1 = s.width / 2 - h.heated_length / 2, s.width / 2 + h.heated_length / 2
        out.append((f"h{i + 1}", np.array([x, y0, h.distance]), np.array([x, y1, h.distance]), h.diameter / 2))
    for j in range(v.count):
        y = s.width / 2 + (j - (v.count - 1) / 2) * v.pitch
        x0, x1 = s.length / 2 - v.heated_length / 2, s.length / 2 + v.heated_length / 2
        out.append((f"v{j + 1}", np.array([x0, y, -v.distance]), np.array([x1, y, -v.distance]), v.diameter / 2))
    return out


def _specimen_face(cfg: FurnaceConfig, eta: float, front: bool) -> list[tuple[Array, IntArray]]:
    s = cfg.specimen
    dx, dy = s.length / s.nx, s.width / s.ny
    z = s.thickness / 2 if front else -s.thickness / 2
    cells = []
    for j in range(s.ny):
        for i in range(s.nx):
            corner = np.array([eta + i * dx, j * dy, z])
            u, v = np.array([dx, 0, 0]), np.array([0, dy, 0])
            cells.append(rectangle(corner, u, v) if front else rectangle(corner, v, u))
    return cells


def _housing_sections(cfg: FurnaceConfig) -> list[list[tuple[Array, IntArray]]]:
    (x0, x1), (y0, y1), (z0, z1) = cfg.housing_x_range, cfg.housing_y_range, cfg.housing_z_range
    n = cfg.housing.sections
    edges = np.linspace(x0, x1, n + 1)
    dz = np.array([0, 0, z1 - z0])
    sections: list[list[tuple[Array, IntArray]]] = []
    for b in range(n):
        dx = np.array([edges[b + 1] - edges[b], 0, 0])
        parts = [
            rectangle(np.array([edges[b], y0, z0]), dz, dx),  # y = y0, normal +y
            rectangle(np.array([edges[b], y1, z0]), dx, dz),  # y = y1, normal -y
        ]
        if b == 0:
            parts.append(rectangle(np.array([x0, y0, z0]), np.array([0, y1 - y0, 0]), dz))  # +x
        if b == n - 1:
            parts.append(rectangle(np.array([x1, y0, z0]), dz, np.array([0, y1 - y0, 0])))  # -x
        sections.append(parts)
    return sections


def _reflectors(cfg: FurnaceConfig) -> list[tuple[Array, IntArray]]:
    (x0, x1), (y0, y1), (z0, z1) = cfg.housing_x_range, cfg.housing_y_range, cfg.housing_z_range
    ex, ey = np.array([x1 - x0, 0, 0]), np.array([0, y1 - y0, 0])
    top = rectangle(np.array([x0, y0, z1]), ey, ex)  # faces -z (into the chamber)
    bottom = rectangle(np.array([x0, y0, z0]), ex, ey)  # faces +z
    return [top, bottom]


def _holder_jaws(cfg: FurnaceConfig, eta: float, upper: bool) -> list[tuple[Array, IntArray]]:
    s, h = cfg.specimen, cfg.holders
    if upper:
        xa, xb = eta - h.arm_length, eta + h.clamp_length
    else:
        xa, xb = eta + s.length - h.clamp_length, eta + s.length + h.arm_length
    ya, yb = -h.jaw_overhang, s.width + h.jaw_overhang
    zin = s.thickness / 2 + CONTACT_GAP
    front = box(np.array([xa, ya, zin]), np.array([xb, yb, zin + h.jaw_thickness]))
    back = box(np.array([xa, ya, -zin - h.jaw_thickness]), np.array([xb, yb, -zin]))
    return [front, back]


def furnace_geometry(cfg: FurnaceConfig, eta: float) -> FurnaceGeometry:
    """All radiating surfaces with the specimen and holders at position ``eta`` (m).

    Parameters
    ----------
    cfg : furnace configuration
    eta : specimen position (m), paper eq. (4); the specimen spans eta <= x <= eta + L_s

    Returns
    -------
    FurnaceGeometry
        surfaces in the order front cells, back cells, walls, lamps
    """
    s, lamps, refl, hous, hold = cfg.specimen, cfg.lamps, cfg.reflector, cfg.housing, cfg.holders
    n_s = s.n_states
    parts: list[tuple[int, Array, IntArray]] = []
    names: list[str] = []
    eps: list[float] = []
    rho_s: list[float] = []
    rho_d: list[float] = []

    def add(name: str, geo: list[tuple[Array, IntArray]], e: float, rs: float, rd: float) -> None:
        idx = len(names)
        names.append(name)
        eps.append(e)
        rho_s.append(rs)
        rho_d.append(rd)
        parts.extend((idx, v, f) for v, f in geo)

    for front in (True, False):
        side = "front" if front else "back"
        for k, cell in enumerate(_specimen_face(cfg, eta, front)):
            add(f"specimen_{side}_{k}", [cell], s.emissivity, s.specular_reflectivity, s.diffuse_reflectivity)

    wall_t: list[float] = []
    top, bottom = _reflectors(cfg)
    for name, rect in (("reflector_h", top), ("reflector_v", bottom)):
        add(name, [rect], refl.emissivity, refl.specular_reflectivity, refl.diffuse_reflectivity)
        wall_t.append(refl.temperature)
    for b, sec in enumerate(_housing_sections(cfg)):
        add(f"housing_{b + 1}", sec, hous.emissivity, hous.specular_reflectivity, hous.diffuse_reflectivity)
        wall_t.append(hous.temperature)
    for name, upper, t in (
        ("holder_upper", True, hold.temperature_upper),
        ("holder_lower", False, hold.temperature_lower),
    ):
        add(name, _holder_jaws(cfg, eta, upper), hold.emissivity, hold.specular_reflectivity,
            hold.diffuse_reflectivity)
        wall_t.append(t)
    n_w = len(wall_t)

    nominal = []
    for name, p0, p1, r in lamp_axes(cfg):
        add(name, [cylinder(p0, p1, r)], lamps.emissivity, lamps.specular_reflectivity, lamps.diffuse_reflectivity)
        nominal.append(2 * math.pi * r * float(np.linalg.norm(p1 - p0)))

    enc = build_enclosure(parts, np.array(rho_s))
    return FurnaceGeometry(
        eta=float(eta),
        enclosure=enc,
        names=tuple(names),
        n_specimen=n_s,
        n_walls=n_w,
        n_lamps=lamps.n_lamps,
        emissivity=np.array(eps),
        specular_reflectivity=np.array(rho_s),
        diffuse_reflectivity=np.array(rho_d),
        wall_names=tuple(names[2 * n_s : 2 * n_s + n_w]),
        wall_temperatures=np.array(wall_t),
        lamp_nominal_area=np.array(nominal),
    )


def specimen_plate_mesh(cfg: FurnaceConfig, eta: float) -> tuple[Array, IntArray, IntArray]:
    """The specimen's front face as a vertex grid, for colouring in the 3D view.

    Returns
    -------
    vertices : ((N_x+1)(N_y+1), 3) m, vertex (i, j) at index i + (N_x+1) j
    faces : (2 N_s, 3) triangles
    face_cell : (2 N_s,) FD cell k = i + N_x j of each triangle
    """
    s = cfg.specimen
    xs = eta + np.linspace(0, s.length, s.nx + 1)
    ys = np.linspace(0, s.width, s.ny + 1)
    X, Y = np.meshgrid(xs, ys)  # (ny+1, nx+1), row-major over j then i
    verts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, s.thickness / 2)])
    faces, cell = [], []
    w = s.nx + 1
    for j in range(s.ny):
        for i in range(s.nx):
            a = i + w * j
            faces += [[a, a + 1, a + 1 + w], [a, a + 1 + w, a + w]]
            cell += [i + s.nx * j] * 2
    return verts, np.array(faces, np.int64), np.array(cell, np.int64)


def display_meshes(cfg: FurnaceConfig, eta: float) -> list[tuple[str, str, Array, IntArray]]:
    """Triangle meshes for the 3D view: ``(name, kind, vertices (n, 3) m, faces (m, 3))``.

    kinds: ``specimen``, ``lamp``, ``reflector``, ``housing``, ``holder``, ``window``.
    The housing sections are included (kind ``housing``); a viewer may hide them.
    """
    out: list[tuple[str, str, Array, IntArray]] = []
    v, f, _ = specimen_plate_mesh(cfg, eta)
    out.append(("specimen", "specimen", v, f))
    for name, p0, p1, r in lamp_axes(cfg):
        out.append((name, "lamp", *cylinder(p0, p1, r, 16)))
    for name, rect in zip(("reflector_h", "reflector_v"), _reflectors(cfg), strict=True):
        out.append((name, "reflector", *rect))
    for b, sec in enumerate(_housing_sections(cfg)):
        out.append((f"housing_{b + 1}", "housing", *_merge(sec)))
    for name, upper in (("holder_upper", True), ("holder_lower", False)):
        out.append((name, "holder", *_merge(_holder_jaws(cfg, eta, upper))))
    (x0, x1), (y0, y1) = cfg.housing_x_range, cfg.housing_y_range
    win = rectangle(np.array([x0, y0, -cfg.window.distance]), np.array([x1 - x0, 0, 0]), np.array([0, y1 - y0, 0]))
    out.append(("window", "window", *win))
    return out


def _merge(parts: list[tuple[Array, IntArray]]) -> tuple[Array, IntArray]:
    verts, faces, off = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + off)
        off += len(v)
    return np.vstack(verts), np.vstack(faces)
