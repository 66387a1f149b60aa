"""The radiation model of the specimen: q_r = P1(eta) [T^4; T_w^4] + P2(eta) u (paper eq. 4).

:func:`radiation_model` loads the exchange factors F^s(eta_n) from the disk cache (or
ray-traces them), builds P1(eta_n), P2(eta_n) at every table position (eq. 5) and
returns a frozen :class:`RadiationModel` that interpolates them linearly in eta with
hat-function weights, without building a matrix per call.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> rad = radiation_model(small_config())
>>> q = rad.flux(np.full(442, 1000.0), np.zeros(len(rad.lamp_flux_max)), 0.0)   # lamps off: the plate loses heat
>>> bool((q > 0).all())
True
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.physics.geometry import furnace_geometry
from twin.physics.motion import hat_weights
from twin.radiation.net_radiation import net_radiation_matrix, specimen_matrices

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SurfaceOptics:
    """Per-surface optics and bookkeeping needed to rebuild P from F^s (order of the geometry)."""

    emissivity: Array
    specular: Array
    diffuse: Array
    lamp_flux_scale: Array  # pi d l / modelled lamp area
    n_specimen: int
    n_walls: int

    def with_specimen_emissivity(self, eps: float) -> SurfaceOptics:
        """Specimen cells get emissivity eps; their specular part stays, the diffuse part takes the rest."""
        n2 = 2 * self.n_specimen
        e, d = self.emissivity.copy(), self.diffuse.copy()
        rho_d = 1.0 - eps - self.specular[:n2]
        if eps <= 0 or np.any(rho_d < -1e-12):
            raise ValueError(f"specimen emissivity {eps} impossible with specular reflectivity {self.specular[0]}")
        e[:n2], d[:n2] = eps, np.maximum(rho_d, 0.0)
        return replace(self, emissivity=e, diffuse=d)


def build_matrices(F: NDArray[Any], optics: SurfaceOptics) -> tuple[Array, Array]:
    """P1 (n_eta, N_s, N_s + N_w) and P2 (n_eta, N_s, N_lamps) from F^s (n_eta, n, n), eqs. (4)-(5)."""
    P1s, P2s = [], []
    for Fk in F:
        P = net_radiation_matrix(np.asarray(Fk, float), optics.emissivity, optics.specular, optics.diffuse)
        P1, P2 = specimen_matrices(P, optics.n_specimen, optics.n_walls, optics.lamp_flux_scale)
        P1s.append(P1)
        P2s.append(P2)
    return np.stack(P1s), np.stack(P2s)


def surface_optics(cfg: FurnaceConfig) -> SurfaceOptics:
    """Optics of the furnace surfaces (they do not depend on eta)."""
    geo = furnace_geometry(cfg, 0.0)
    lamp_area = geo.area[2 * geo.n_specimen + geo.n_walls :]
    return SurfaceOptics(
        geo.emissivity, geo.specular_reflectivity, geo.diffuse_reflectivity,
        geo.lamp_nominal_area / lamp_area, geo.n_specimen, geo.n_walls,
    )


@dataclass(frozen=True, eq=False)
class RadiationModel:
    """Net radiative flux leaving the specimen, eq. (4), tabulated at eta_n and interpolated.

    Attributes
    ----------
    eta_nodes : (n_eta,) m
    P1 : (n_eta, N_s, N_s + N_w) W/(m^2 K^4), sigma inside
    P2 : (n_eta, N_s, N_lamps) dimensionless
    wall_temperatures : (N_w,) K, default T_w
    wall_names : names of the wall surfaces
    lamp_flux_max : (N_lamps,) W/m^2, rated_power / (pi d l)
    exchange : (n_eta, n, n) F^s, kept for :meth:`with_specimen_emissivity`
    optics : :class:`SurfaceOptics`
    """

    eta_nodes: Array
    P1: Array
    P2: Array
    wall_temperatures: Array
    wall_names: tuple[str, ...]
    lamp_flux_max: Array
    exchange: NDArray[Any]
    optics: SurfaceOptics
    #: the disk cache's file of this table (:func:`radiation_model`); matrices for another specimen emissivity
    #: are kept beside it (:meth:`with_specimen_emissivity`).  None: built every time (a table made in memory)
    cache_file: Path | None = None

    @property
    def n_specimen(self) -> int:
        return int(self.P1.shape[1])

    def weights(self, eta: float) -> Array:
        """Hat-function weights (n_eta,) of linear interpolation in eta (:func:`twin.physics.motion.hat_weights`)."""
        return hat_weights(self.eta_nodes, eta)

    def matrices(self, eta: float) -> tuple[Array, Array]:
        """Interpolated P1(eta), P2(eta) (builds two matrices; use :meth:`flux` in loops)."""
        w = self.weights(eta)
        idx = np.flatnonzero(w)
        P1 = sum(w[k] * self.P1[k] for k in idx)
        P2 = sum(w[k] * self.P2[k] for k in idx)
        return np.asarray(P1), np.asarray(P2)

    def flux(self, T: ArrayLike, u_lamp: ArrayLike, eta: float, T_w: ArrayLike | None = None) -> Array:
        """q_r (N_s,) in W/m^2 of plate area, both faces, positive = leaving the specimen (eq. 4).

        Parameters
        ----------
        T : (N_s,) K specimen cell temperatures
        u_lamp : (N_lamps,) W/m^2 net flux at the lamp surfaces (order h_1..h_Nh, v_1..v_Nv)
        eta : m specimen position
        T_w : (N_w,) K wall temperatures (default :attr:`wall_temperatures`)
        """
        Tw = self.wall_temperatures if T_w is None else np.asarray(T_w, float)
        x = np.concatenate([np.asarray(T, float) ** 4, Tw**4])
        u = np.asarray(u_lamp, float)
        w = self.weights(eta)
        q = np.zeros(self.n_specimen)
        for k in np.flatnonzero(w):
            q += w[k] * (self.P1[k] @ x + self.P2[k] @ u)
        return q

    def with_specimen_emissivity(self, eps: float) -> RadiationModel:
        """The same furnace with another specimen emissivity (plant mismatch, the model's emissivity
        sensitivity); F^s is reused.  P1, P2 of eq. (5) for ``eps`` depend on F^s, the optics and ``eps`` alone
        (the specimen's optics are set, not scaled): with a cached table they are built once and kept beside it
        (:func:`twin.radiation.cache.emissivity_matrices`), not again in every run (a 240 s default run built
        them three times, about 1.5 s each)."""
        optics = self.optics.with_specimen_emissivity(eps)
        if self.cache_file is None:
            P1, P2 = build_matrices(self.exchange, optics)
        else:
            from twin.radiation.cache import emissivity_matrices

            P1, P2 = emissivity_matrices(self.cache_file, float(eps), lambda: build_matrices(self.exchange, optics))
        return replace(self, P1=P1, P2=P2, optics=optics)


def lamp_flux_max(cfg: FurnaceConfig) -> Array:
    """u_max per lamp (W/m^2) = rated_power / (pi d l) (paper, after eq. 2)."""
    lamps = cfg.lamps
    h, v = lamps.horizontal, lamps.vertical
    return np.concatenate(
        [
            np.full(h.count, lamps.rated_power / (math.pi * h.diameter * h.heated_length)),
            np.full(v.count, lamps.rated_power / (math.pi * v.diameter * v.heated_length)),
        ]
    )


def radiation_model(
    cfg: FurnaceConfig, *, cache_dir: str | Path | None = None, progress: bool = False, symmetric: bool = False,
    on_position: Callable[[int, int], None] | None = None,
) -> RadiationModel:
    """Radiation model of ``cfg``: cached F^s (or ray-traced now) and the matrices of eqs. (4)-(5).

    Parameters
    ----------
    cfg : furnace configuration
    cache_dir : directory of the F^s cache (default ``$FURNACE_TWIN_CACHE`` or ``~/.cache/furnace-twin``)
    progress : show a tqdm progress bar while ray tracing
    symmetric : trace with the chamber's mirror symmetries (:mod:`twin.radiation.symmetry`), cached apart
    on_position : ``on_position(done, total)`` as positions are ray-traced (not called on a cache hit)
    """
    from twin.radiation.cache import cache_path, load_or_compute

    table = load_or_compute(cfg, cache_dir=cache_dir, progress=progress, symmetric=symmetric,
                            on_position=on_position)
    geo = furnace_geometry(cfg, 0.0)
    return RadiationModel(
        eta_nodes=table.eta,
        P1=table.P1,
        P2=table.P2,
        wall_temperatures=geo.wall_temperatures,
        wall_names=geo.wall_names,
        lamp_flux_max=lamp_flux_max(cfg),
        exchange=table.F,
        optics=table.optics,
        cache_file=cache_path(cfg, cache_dir, symmetric=symmetric),
    )
