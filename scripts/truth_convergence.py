"""How converged and how symmetric is the simulated furnace's own radiation table?  (issue 10)

Two studies, each printing a table (all differences relative to the setpoint 1100 K):

``--study eta0`` (cheap): the eta = 0 table alone, traced symmetrically at the truth's ray counts
times each ``--factors`` entry; the steady true field of the fixed specimen (truth plant, its
deviations) at one fixed set of group powers (those that hold the fillet mean at 1100 K on the
first table) is compared between consecutive factors: max |dT| over the plate and over the fillet.
It also reports the mirror asymmetry max |T(x, y) - T(x, W_s - y)| of the steady field on the
model's table (the plant of ``"truth": "shared"``) and on the truth's.

``--study full``: the truth's whole table (all eta positions, cached) against the same table with
twice the rays (traced into ``--scratch``), steady fields of the fixed and of the oscillating
specimen (period-averaged tables, the paper's oscillation 3 L_h, 0.15 t_E).

Run under ``nice -n 19``: the full study traces a table with twice the truth's rays.

    nice -n 19 .venv/bin/python scripts/truth_convergence.py --config default --study eta0 --factors 1,2,4
    nice -n 19 .venv/bin/python scripts/truth_convergence.py --config banded --study full
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from typing import Any

import numpy as np

from twin.config import load_config
from twin.furnace.simulated.plant import Plant
from twin.furnace.simulated.steady import steady_powers, steady_weights
from twin.furnace.simulated.truth import deviations, truth_radiation_config, with_latent_heat
from twin.physics.geometry import furnace_geometry
from twin.radiation import radiation_model
from twin.radiation.exchange import rays_per_surface
from twin.radiation.model import RadiationModel, build_matrices, lamp_flux_max, surface_optics
from twin.radiation.symmetry import group_of, reflection, surface_permutation, symmetric_exchange_factors
from twin.scenario import OscillationSpec

SETPOINT = 1100.0


def say(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def scaled(cfg: Any, factor: float) -> Any:
    """The truth's radiation config with ``factor`` times its rays."""
    r = cfg.truth.radiation
    return truth_radiation_config(cfg.with_overrides({
        "truth.radiation.rays_per_specimen_cell": int(round(r.rays_per_specimen_cell * factor)),
        "truth.radiation.rays_per_lamp": int(round(r.rays_per_lamp * factor)),
        "truth.radiation.rays_per_wall": int(round(r.rays_per_wall * factor)),
    }))


def eta0_model(rcfg: Any) -> RadiationModel:
    """A one-position radiation model (eta = 0) traced with the full symmetry group."""
    geo = furnace_geometry(rcfg, 0.0)
    gens = [p for p in (surface_permutation(geo, geo, reflection(rcfg, a)) for a in "xy") if p is not None]
    group = group_of(gens, geo.n_surfaces)
    r = rcfg.radiation
    F, msg, _ = symmetric_exchange_factors(geo, group, rays_per_surface(rcfg, geo), max_bounces=r.max_specular_bounces,
                                           min_weight=r.min_ray_weight, rng=np.random.default_rng(r.seed))
    logging.info("%s", msg)
    optics = surface_optics(rcfg)
    F32 = F[None].astype(np.float32)
    P1, P2 = build_matrices(F32, optics)
    return RadiationModel(np.zeros(1), P1, P2, geo.wall_temperatures, geo.wall_names, lamp_flux_max(rcfg), F32,
                          optics)


def truth_plant(cfg: Any, radiation: Any) -> Plant:
    return Plant(with_latent_heat(cfg), radiation, deviations(cfg, None), radiation_dtype=np.float64)


def asymmetry(cfg: Any, T: np.ndarray) -> float:
    f = T.reshape(cfg.specimen.ny, cfg.specimen.nx)
    return float(np.abs(f - f[::-1]).max()) / SETPOINT


def compare(plant_a: Plant, plant_b: Plant, u: np.ndarray, w_a: Any, w_b: Any) -> tuple[float, float]:
    Ta = plant_a.steady_state(u, w_a)
    Tb = plant_b.steady_state(u, w_b, Ta)
    d = np.abs(Ta - Tb)
    return float(d.max()) / SETPOINT, float(d[plant_a.fillet_mask].max()) / SETPOINT


def study_eta0(cfg: Any, factors: list[float]) -> None:
    shared = Plant(cfg, radiation_model(cfg), radiation_dtype=np.float64)
    sp_model = steady_powers(shared)
    say(f"model's table (truth 'shared'): steady field asymmetry {100 * asymmetry(cfg, sp_model.T):.3f} %")
    plants, u = [], None
    for f in factors:
        t0 = time.perf_counter()
        plant = truth_plant(cfg, eta0_model(scaled(cfg, f)))
        dt = time.perf_counter() - t0
        if u is None:
            u = steady_powers(plant).u
        T = plant.steady_state(u)
        line = f"truth x{f:g}: eta = 0 traced in {dt:.1f} s, asymmetry {100 * asymmetry(cfg, T):.2e} %"
        if plants:
            plate, fillet = compare(plants[-1], plant, u, None, None)
            line += (f"; vs x{factors[len(plants) - 1]:g}: max |dT| plate {100 * plate:.3f} %, "
                     f"fillet {100 * fillet:.3f} %")
        say(line)
        plants.append(plant)


def study_full(cfg: Any, scratch: str) -> None:
    osc = OscillationSpec(enabled=True, amplitude=min(3 * cfg.lamps.horizontal.pitch, cfg.oscillation.eta_max),
                          period=18.0)
    t0 = time.perf_counter()
    nominal = truth_plant(cfg, radiation_model(scaled(cfg, 1.0), symmetric=True))
    t1 = time.perf_counter()
    double = truth_plant(cfg, radiation_model(scaled(cfg, 2.0), symmetric=True, cache_dir=scratch))
    t2 = time.perf_counter()
    say(f"truth table (nominal rays): {t1 - t0:.1f} s (cached: load only); twice the rays: {t2 - t1:.1f} s")
    for name, spec in (("fixed", None), ("oscillating", osc)):
        u = steady_powers(nominal, oscillation=spec).u
        w = steady_weights(nominal, spec)
        plate, fillet = compare(nominal, double, u, w, w)
        T = nominal.steady_state(u, w)
        say(f"{name}: u = {np.round(u, 3).tolist()}; doubling the rays moves the steady true field by max "
              f"{100 * plate:.3f} % (plate), {100 * fillet:.3f} % (fillet) of the setpoint; asymmetry "
              f"{asymmetry(cfg, T):.1e}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", default="default")
    p.add_argument("--study", choices=("eta0", "full"), default="eta0")
    p.add_argument("--factors", default="1,2", help="ray multipliers of the eta0 study")
    p.add_argument("--scratch", default=None, help="cache directory of the doubled table (default: temporary)")
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    cfg = load_config(args.config)
    if args.study == "eta0":
        study_eta0(cfg, [float(v) for v in args.factors.split(",")])
    elif args.scratch:
        study_full(cfg, args.scratch)
    else:
        with tempfile.TemporaryDirectory(prefix="truth-convergence-") as d:
            study_full(cfg, d)


if __name__ == "__main__":
    main()
