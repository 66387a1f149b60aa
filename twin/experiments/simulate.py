"""``furnace-twin simulate``: an open-loop run of the simulated furnace with constant or scheduled group powers.

The furnace is the scenario's (``--truth independent``, the default: its own tables, latent heat, lagging
and biased TCs, lagging lamps; ``--truth shared``: the model's plant with ideal sensors).

Writes ``timeseries.npz`` (t, eta, u (n, 6), tc (n, 4), tc_true, fillet_mean,
inhomogeneity, t_field, field (m, N_y, N_x), x, y, L_s, W_s, tc_positions, group_names)
and two PNGs: ``field.png`` (final field, fillet outline, TC markers) and ``tc.png``
(the four TC traces, fillet mean, group powers, eta).

Schedule file: JSON ``[[t, [u1, ..., u6]], ...]`` with increasing t (s); each entry holds
from its time on (zero-order hold); before the first entry ``--powers`` applies.

Example
-------
    furnace-twin simulate --powers 0.55 --duration 240 --oscillate --out out/sim
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import ValidationError

from twin.config import FurnaceConfig
from twin.limits import furnace_name, scenario_limits
from twin.physics.fillet import fillet_box
from twin.scenario import MAX_DURATION_S, OscillationSpec, parse_oscillation, parse_scenario
from twin.user_files import read_json

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class SimulateArgumentError(ValueError):
    """A bad ``simulate`` argument; the message says which and why."""


def parse_powers(text: str, n_groups: int) -> Array:
    """One fraction for every group, or ``n_groups`` comma-separated fractions, all in [0, 1]."""
    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise SimulateArgumentError(
            f"--powers: expected numbers like 0.6 or 0.5,0.5,0.6,0.7,0.4,0.4, got {text!r}"
        ) from None
    if len(values) == 1:
        values = values * n_groups
    if len(values) != n_groups:
        raise SimulateArgumentError(f"--powers: need 1 or {n_groups} values (one per group), got {len(values)}")
    u = np.array(values, float)
    if not np.all(np.isfinite(u)) or np.any(u < 0.0) or np.any(u > 1.0):
        raise SimulateArgumentError("--powers: fractions of u_max must lie in [0, 1]")
    return u


def load_schedule(path: str, n_groups: int) -> tuple[Array, Array]:
    """Times (k,) and powers (k, n_groups) of a schedule file (see the module docstring)."""
    try:
        data = read_json(path, "schedule", SimulateArgumentError)
    except SimulateArgumentError as exc:
        raise SimulateArgumentError(f"--schedule: {exc}") from None
    if not isinstance(data, list) or not data:
        raise SimulateArgumentError("--schedule: expected a non-empty list [[t, [u1..u6]], ...]")
    times, powers = [], []
    for i, entry in enumerate(data):
        if not (isinstance(entry, list) and len(entry) == 2 and isinstance(entry[1], list)):
            raise SimulateArgumentError(f"--schedule: entry {i} must look like [t, [u1, ..., u{n_groups}]]")
        try:
            t = float(entry[0])
            u = parse_powers(",".join(str(v) for v in entry[1]), n_groups)
        except (TypeError, ValueError) as exc:
            raise SimulateArgumentError(f"--schedule: entry {i}: {exc}") from None
        if len(entry[1]) != n_groups:
            raise SimulateArgumentError(f"--schedule: entry {i} needs {n_groups} powers, got {len(entry[1])}")
        times.append(t)
        powers.append(u)
    ts = np.array(times)
    if ts[0] < 0 or np.any(np.diff(ts) <= 0):
        raise SimulateArgumentError("--schedule: times must be >= 0 and strictly increasing")
    return ts, np.array(powers)


@dataclass(frozen=True)
class OpenLoopRun:
    """Samples of an open-loop run (every t_s; the field every ``field_every`` s)."""

    t: Array
    eta: Array
    u: Array
    tc: Array
    tc_true: Array
    fillet_mean: Array
    inhomogeneity: Array
    t_field: Array
    field: Array


def run_open_loop(
    furnace: Any,
    u_of_t: Callable[[float], Array],
    duration: float,
    field_every: float = 1.0,
) -> OpenLoopRun:
    """March a simulated furnace (:class:`twin.furnace.simulated.SimulatedFurnace`) from its initial state,
    reading its TCs at every sample t_s; ``tc_true`` is the plate under each TC, ``tc`` what the TC reads
    (lag, bias and noise of the furnace's truth)."""
    plant, dt = furnace.plant, furnace.t_s
    n = int(round(duration / dt))
    every = max(1, int(round(field_every / dt)))
    t = np.arange(n + 1) * dt
    eta = np.empty(n + 1)
    u = np.empty((n + 1, plant.n_groups))
    tc = np.empty((n + 1, len(furnace.tc_positions)))
    tc_true = np.empty_like(tc)
    means = np.empty(n + 1)
    inh = np.empty(n + 1)
    t_field, fields = [], []
    for j in range(n + 1):
        T = furnace.true_field()
        eta[j] = furnace.motion(t[j]).eta
        u[j] = u_of_t(t[j])
        tc[j] = furnace.read(t[j]).values
        tc_true[j] = furnace.thermocouples.true_values(T)
        means[j] = plant.fillet_mean(T)
        inh[j] = plant.fillet_inhomogeneity(T)
        if j % every == 0 or j == n:
            t_field.append(t[j])
            fields.append(plant.field(T))
        if j < n:
            furnace.apply(u[j], t[j])
    return OpenLoopRun(t, eta, u, tc, tc_true, means, inh, np.array(t_field), np.array(fields))


def _oscillation(cfg: FurnaceConfig, args: Any) -> OscillationSpec:
    """--oscillate / --amplitude / --period, checked against the furnace (``twin.limits``); an option
    left out (None) takes the furnace's default."""
    if not args.oscillate:
        return OscillationSpec.model_validate({"enabled": False})
    given = {"amplitude": args.amplitude, "period": args.period}
    try:
        return parse_oscillation({"enabled": True, **{k: v for k, v in given.items() if v is not None}},
                                 scenario_limits(cfg, furnace_name(cfg, getattr(args, "config", None))))
    except ValidationError as exc:
        msgs = "; ".join(f"--{e['loc'][-1]}: {e['msg'].removeprefix('Value error, ')}" for e in exc.errors())
        raise SimulateArgumentError(msgs) from None


def _scenario(cfg: FurnaceConfig, args: Any, spec: OscillationSpec) -> Any:
    """The furnace's side of a scenario: oscillation, TC4, seed, truth (``--truth``, default independent)."""
    data = {"oscillation": spec.model_dump(), "tc4": list(args.tc4), "seed": args.seed,
            "truth": getattr(args, "truth", "independent")}
    try:
        return parse_scenario(data, scenario_limits(cfg, furnace_name(cfg, getattr(args, "config", None))))
    except ValidationError as exc:
        msgs = "; ".join(f"--{e['loc'][-1]}: {e['msg'].removeprefix('Value error, ')}" for e in exc.errors())
        raise SimulateArgumentError(msgs) from None


def simulate_command(cfg: FurnaceConfig, args: Any) -> int:
    """Entry point of ``furnace-twin simulate`` (argument parsing lives in furnace_twin.cli)."""
    from twin.experiments.figures_open_loop import plot_field, plot_tc_traces
    from twin.furnace.simulated import SimulatedFurnace
    from twin.radiation import radiation_model

    try:
        u_const = parse_powers(args.powers, cfg.n_groups)
        if not (np.isfinite(args.duration) and 0 < args.duration <= MAX_DURATION_S):
            raise SimulateArgumentError(f"--duration: must be in (0, {MAX_DURATION_S:g}] s, got {args.duration}")
        spec = _oscillation(cfg, args)
        sched = load_schedule(args.schedule, cfg.n_groups) if args.schedule else None
        scenario = _scenario(cfg, args, spec)
    except SimulateArgumentError as exc:
        print(f"furnace-twin simulate: {exc}", file=sys.stderr)  # noqa: T201
        return 2

    def u_of_t(t: float) -> Array:
        if sched is None:
            return u_const
        k = int(np.searchsorted(sched[0], t + 1e-9, side="right")) - 1
        return u_const if k < 0 else sched[1][k]

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth = scenario.truth
    rad = radiation_model(cfg, progress=True)
    own = None
    if truth == "independent":
        from twin.furnace.simulated.truth import truth_radiation

        own = truth_radiation(cfg, progress=True)
    furnace = SimulatedFurnace.for_scenario(cfg, scenario, rad, truth_radiation=own)
    plant = furnace.plant
    positions = cfg.tc_positions(tuple(args.tc4))
    log.info("simulate: %.0f s open loop, oscillation %s, truth %s", args.duration,
             "on" if spec.enabled else "off", truth)
    run = run_open_loop(furnace, u_of_t, args.duration)
    names = [g.name for g in cfg.lamps.groups]
    s = cfg.specimen
    np.savez_compressed(
        out / "timeseries.npz",
        t=run.t,
        eta=run.eta,
        u=run.u,
        tc=run.tc,
        tc_true=run.tc_true,
        fillet_mean=run.fillet_mean,
        inhomogeneity=run.inhomogeneity,
        t_field=run.t_field,
        field=run.field,
        x=plant.x_centers,
        y=plant.y_centers,
        L_s=s.length,
        W_s=s.width,
        tc_positions=np.array(positions),
        group_names=np.array(names),
    )
    title = (
        f"t = {run.t[-1]:.0f} s, fillet mean {run.fillet_mean[-1]:.0f} K, "
        f"inhomogeneity {100 * run.inhomogeneity[-1] / run.fillet_mean[-1]:.1f} %"
        + (f", eta = {1e3 * run.eta[-1]:.1f} mm" if spec.enabled else "")
    )
    plot_field(
        out / "field.png",
        run.field[-1],
        plant.x_centers,
        plant.y_centers,
        s.length,
        s.width,
        fillet_box(s.length, s.width),
        positions,
        title=title,
    )
    plot_tc_traces(
        out / "tc.png",
        run.t,
        run.tc,
        run.fillet_mean,
        run.u,
        run.eta,
        names,
        title="open loop: " + ("oscillating" if spec.enabled else "fixed specimen"),
    )
    log.info(
        "simulate: final fillet mean %.1f K, inhomogeneity %.1f K; wrote %s",
        run.fillet_mean[-1],
        run.inhomogeneity[-1],
        out,
    )
    return 0
