"""The simulated furnace's truth: how the plant differs from the twin's model (the furnace file's ``[truth]``).

A scenario's ``"truth": "independent"`` (the default) runs the plant

* on its own exchange factors, an independent ray trace with another seed and more rays than the
  model's, traced with the chamber's mirror symmetries (:mod:`twin.radiation.symmetry`) and cached
  apart from the model's table (:func:`truth_radiation_config`, :func:`truth_radiation`);
* with the latent heat of the alpha-gamma transformation in c_p (:func:`with_latent_heat`): a
  triangle of area ``latent_heat`` over ``transformation_range`` added to the c_p table, so that the
  enthalpy h(T) (``Steel.enthalpy``, the plant's stored energy) carries it exactly;
* with thermocouples that lag (first order) and read a bias drawn from the run's seed, and lamps
  whose radiated power lags the thyristor command (:mod:`twin.furnace.simulated.sensors`);
* with the deviations of emissivity, convection and lamp efficiency of ``[truth.deviations]``, to
  which a scenario's ``mismatch`` adds (:func:`deviations`).

``"truth": "shared"`` is the comparison case: the model's own tables, ideal TCs and lamps, the
scenario's mismatch alone.  The twin's side (model, EKF, controller) never reads any of this.

Example
-------
>>> from twin.config import small_config
>>> from twin.physics.materials import Steel
>>> cfg = small_config()
>>> model, plant = Steel.from_config(cfg), Steel.from_config(with_latent_heat(cfg))
>>> round(float(plant.enthalpy(1200.0) - model.enthalpy(1200.0)))     # J/kg: the latent heat, all of it
18000
>>> round(float(plant.enthalpy(900.0) - model.enthalpy(900.0)))       # none below the transformation
0
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import FurnaceConfig
from twin.scenario import Mismatch

log = logging.getLogger(__name__)


def truth_radiation_config(cfg: FurnaceConfig) -> FurnaceConfig:
    """``cfg`` with ``[radiation]``'s ray counts and seed replaced by ``[truth.radiation]``'s: what the
    furnace's own table is traced with (the rest of ``[radiation]`` and the geometry are shared)."""
    r = cfg.truth.radiation
    return cfg.with_overrides({
        "radiation.rays_per_specimen_cell": r.rays_per_specimen_cell,
        "radiation.rays_per_lamp": r.rays_per_lamp,
        "radiation.rays_per_wall": r.rays_per_wall,
        "radiation.seed": r.seed,
    })


def truth_radiation(cfg: FurnaceConfig, *, cache_dir: str | Path | None = None, progress: bool = False,
                    on_position: Callable[[int, int], None] | None = None) -> Any:
    """The furnace's own radiation model (symmetric trace of :func:`truth_radiation_config`, cached);
    ``on_position(done, total)`` follows a ray trace (a server's warm-up)."""
    from twin.radiation import radiation_model

    return radiation_model(truth_radiation_config(cfg), cache_dir=cache_dir, progress=progress, symmetric=True,
                           on_position=on_position)


def precompute_truth(cfg: FurnaceConfig, force: bool = False) -> None:
    """``furnace-twin precompute``'s second table: the furnace's own (progress bar, logged)."""
    from twin.radiation.cache import precompute_table

    log.info("the simulated furnace's own exchange factors (its [truth.radiation])")
    precompute_table(truth_radiation_config(cfg), force, symmetric=True)


def with_latent_heat(cfg: FurnaceConfig) -> FurnaceConfig:
    """``cfg`` whose c_p table carries the transformation's latent heat (a triangle over its range).

    The triangle's corners are added to the table's temperatures; c_p and lambda keep their values
    in between (both tables stay piecewise linear on the union of the points), c_p gains the triangle.
    """
    m, t = cfg.material, cfg.truth.material
    lo, hi = t.transformation_range
    if t.latent_heat == 0.0:
        return cfg
    peak = 2.0 * t.latent_heat / (hi - lo)  # J/(kg K): triangle of area latent_heat
    corners = np.array([lo, 0.5 * (lo + hi), hi])
    temps = np.union1d(np.asarray(m.temperatures, float), corners)
    cp = np.interp(temps, m.temperatures, m.heat_capacity) + np.interp(temps, corners, [0.0, peak, 0.0])
    lam = np.interp(temps, m.temperatures, m.conductivity)
    return cfg.with_overrides({
        "material.temperatures": temps.tolist(),
        "material.heat_capacity": cp.tolist(),
        "material.conductivity": lam.tolist(),
    })


def deviations(cfg: FurnaceConfig, mismatch: Mismatch | None) -> Mismatch:
    """The plant's relative deviations from the model: ``[truth.deviations]`` plus the scenario's mismatch.

    The sum may leave the range of one scenario's ``mismatch`` (it is not validated as one); the plant
    refuses what is physically impossible (an emissivity above 1 - specular reflectivity).
    """
    d = cfg.truth.deviations
    m = mismatch or Mismatch()
    return Mismatch.model_construct(
        emissivity=d.emissivity + m.emissivity,
        alpha=d.alpha + m.alpha,
        lamp_efficiency=d.lamp_efficiency + m.lamp_efficiency,
    )


@dataclass(frozen=True)
class Truth:
    """What an independent simulated furnace runs on, built from the furnace file (:meth:`of`).

    Attributes
    ----------
    plant_cfg : the furnace with the latent heat in its c_p table (for the plant only)
    radiation : the furnace's own radiation model
    tc_time_constant : s, first-order lag of every thermocouple
    tc_bias : scale of the per-TC bias, a fraction of the class-1 tolerance band
    lamp_time_constant : s, first-order lag of the radiated power behind the command
    """

    plant_cfg: FurnaceConfig
    radiation: Any
    tc_time_constant: float
    tc_bias: float
    lamp_time_constant: float

    @classmethod
    def of(cls, cfg: FurnaceConfig, radiation: Any = None) -> Truth:
        """The truth of ``cfg``; ``radiation`` is its own table if already loaded (else read from the cache)."""
        t = cfg.truth
        return cls(
            plant_cfg=with_latent_heat(cfg),
            radiation=truth_radiation(cfg) if radiation is None else radiation,
            tc_time_constant=t.thermocouples.time_constant,
            tc_bias=t.thermocouples.bias,
            lamp_time_constant=t.lamps.time_constant,
        )
