"""What the twin has learnt about its furnace, kept between runs (issue 26: a twin that learns its furnace).

A calibrating estimator (:mod:`twin.estimation.joint`) ends each run with relative deviations of the model
(lamp efficiency, emissivity, convection) and their standard deviations (``metrics.json`` ``calibration``).
:class:`CalibrationMemory` keeps the latest learnt values per furnace in the data directory
(``<data_dir>/calibration/<key>.json``: value, sigma, when, from which runs) so that the next run's plan and
its feasibility check start from them (``scenario.control.plan_parameters``) instead of the nominal model.

A furnace here is the furnace file's physics (:func:`furnace_key`) *and* the plant it runs on: a simulated
furnace with its truth and mismatch, or an OPC UA endpoint -- what one learns says nothing about another.

Only parameters the run actually learnt are kept: a value whose sigma is still at least
:data:`LEARNT_FRACTION` of its prior sigma is left out (the estimator saw too little to move it).

Example
-------
>>> import tempfile
>>> from twin.config import small_config
>>> from twin.scenario import Scenario
>>> cfg, scenario = small_config(), Scenario()
>>> memory = CalibrationMemory.of(tempfile.mkdtemp(), cfg, scenario)
>>> memory.plan_parameters() is None
True
>>> _ = memory.learn("run1", {"lamp_efficiency": {"value": -0.12, "sigma": 0.01}}, cfg)
>>> memory.plan_parameters().lamp_efficiency
-0.12
>>> memory.reset(); memory.plan_parameters() is None
True
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.scenario import PlanParameters, Scenario, plant_key, plant_label

log = logging.getLogger(__name__)

#: the furnace file's sections that make its physics (not the twin's settings)
PHYSICAL_SECTIONS = ("specimen", "material", "lamps", "reflector", "housing", "window", "holders", "inert_gas",
                     "oscillation", "radiation", "sensors", "sampling", "fe")
#: a run learnt a parameter when its sigma fell below this fraction of the prior's
LEARNT_FRACTION = 0.5
#: run ids kept per parameter
MAX_RUNS = 20
VERSION = 1


def furnace_key(cfg: FurnaceConfig) -> str:
    """The furnace file's physics as a short hash."""
    return cfg.digest(*PHYSICAL_SECTIONS)


class CalibrationMemory:
    """The JSON file of one furnace and plant (module docstring)."""

    def __init__(self, folder: str | os.PathLike[str], key: str, label: str = "") -> None:
        self.folder = Path(folder)
        self.key = key
        self.label = label
        self.path = self.folder / f"{key}.json"

    @classmethod
    def of(cls, data_dir: str | os.PathLike[str], cfg: FurnaceConfig, scenario: Scenario) -> CalibrationMemory:
        return cls(Path(data_dir) / "calibration", f"{furnace_key(cfg)}-{plant_key(scenario)}", plant_label(scenario))

    def load(self) -> dict[str, Any]:
        """``{"plant", "parameters": {name: {"value", "sigma", "when", "runs"}}, "updated"}``; an empty memory if
        there is none or it cannot be read (logged)."""
        empty: dict[str, Any] = {"plant": self.label, "key": self.key, "parameters": {}, "updated": None}
        try:
            data = json.loads(self.path.read_text())
        except FileNotFoundError:
            return empty
        except (OSError, ValueError) as exc:
            log.warning("calibration memory %s unreadable (%s): starting from the nominal model", self.path, exc)
            return empty
        if not isinstance(data, dict) or data.get("version") != VERSION or not isinstance(data.get("parameters"),
                                                                                          dict):
            log.warning("calibration memory %s has an unknown layout: starting from the nominal model", self.path)
            return empty
        data.pop("version", None)
        return data

    def learn(self, run_id: str, calibration: dict[str, Any], cfg: FurnaceConfig,
              when: datetime | None = None) -> dict[str, Any]:
        """Keep what run ``run_id`` learnt (``metrics.json`` ``calibration``); returns the new memory."""
        data = self.load()
        stamp = (when or datetime.now(UTC)).isoformat(timespec="seconds")
        params: dict[str, Any] = data["parameters"]
        changed = False
        for name, v in calibration.items():
            if not isinstance(v, dict):
                continue
            value, sigma = v.get("value"), v.get("sigma")
            if not isinstance(value, int | float) or not isinstance(sigma, int | float):
                continue
            if not (math.isfinite(value) and math.isfinite(sigma)) or name not in PlanParameters.model_fields:
                continue
            prior = float(getattr(cfg.calibration.prior_sigma, name))
            if sigma >= LEARNT_FRACTION * prior:
                continue
            runs = [*params.get(name, {}).get("runs", []), run_id][-MAX_RUNS:]
            params[name] = {"value": float(value), "sigma": float(sigma), "when": stamp, "runs": runs}
            changed = True
        if changed:
            data.update(parameters=params, updated=stamp, plant=self.label, key=self.key)
            self._write(data)
            log.info("calibration memory %s: learnt from run %s: %s", self.key, run_id,
                     {k: round(p["value"], 4) for k, p in params.items()})
        return data

    def plan_parameters(self, learns: tuple[str, ...] | None = None) -> PlanParameters | None:
        """The learnt deviations for the next plan (only those named in ``learns``, all if None), or None when
        nothing is learnt."""
        params = {name: p["value"] for name, p in self.load()["parameters"].items()
                  if name in PlanParameters.model_fields and (learns is None or name in learns)}
        return PlanParameters(**params) if params else None

    def reset(self) -> None:
        """Forget everything learnt: the next run plans with the nominal model."""
        self.path.unlink(missing_ok=True)
        log.info("calibration memory %s reset", self.key)

    def _write(self, data: dict[str, Any]) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.folder, suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump({"version": VERSION, **data}, f, indent=2)
        os.replace(tmp, self.path)


def memories(data_dir: str | os.PathLike[str], cfg: FurnaceConfig) -> list[CalibrationMemory]:
    """Every plant's memory of this furnace file in the data directory."""
    folder = Path(data_dir) / "calibration"
    prefix = furnace_key(cfg) + "-"
    if not folder.is_dir():
        return []
    out = []
    for path in sorted(folder.glob(prefix + "*.json")):
        mem = CalibrationMemory(folder, path.stem)
        mem.label = str(mem.load().get("plant") or path.stem[len(prefix):])
        out.append(mem)
    return out


def learnt_parameters(calibration: dict[str, Any] | None, cfg: FurnaceConfig) -> PlanParameters | None:
    """What a run's ``calibration`` (``metrics.json``) gives the next plan: the parameters it learnt (module
    docstring) among ``[control] plan_learns``, or None."""
    if not calibration:
        return None
    learnt = {}
    for name in cfg.control.plan_learns:
        v = calibration.get(name)
        if not isinstance(v, dict):
            continue
        value, sigma = v.get("value"), v.get("sigma")
        prior = float(getattr(cfg.calibration.prior_sigma, name))
        if isinstance(value, int | float) and isinstance(sigma, int | float) and math.isfinite(value) \
                and math.isfinite(sigma) and sigma < LEARNT_FRACTION * prior:
            learnt[name] = float(value)
    return PlanParameters(**learnt) if learnt else None


def with_parameters(scenario: Scenario, learnt: PlanParameters | None) -> Scenario:
    """The scenario with ``control.plan_parameters = learnt`` (unchanged if None)."""
    if learnt is None:
        return scenario
    control = scenario.control.model_copy(update={"plan_parameters": learnt})
    return scenario.model_copy(update={"control": control})


def with_memory(scenario: Scenario, data_dir: str | os.PathLike[str], cfg: FurnaceConfig) -> Scenario:
    """The scenario with ``control.plan_parameters`` from the memory (those ``[control] plan_learns`` names),
    unless it gives them itself."""
    if scenario.control.plan_parameters is not None:
        return scenario
    return with_parameters(scenario, CalibrationMemory.of(data_dir, cfg, scenario).plan_parameters(
        cfg.control.plan_learns))
