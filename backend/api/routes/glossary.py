"""``GET /api/glossary``: the words the dashboard explains (its help tooltips), for the loaded furnace.

``metrics``: each metric's name, meaning and unit (``twin.runs.metrics.metric_glossary``: every key a run's
``metrics.json`` can hold; the setpoint-relative errors, also in the report, have the unit
``twin.runs.metrics.RELATIVE``);
``terms``: fillet, t_E, eta, u, u_ff, the lamp groups (each one's lamps, from the furnace), TC4,
T_sup, spread, the metric windows, saturation, feasibility.  One place for these texts.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from backend.api.deps import ManagerDep
from twin.config import FurnaceConfig
from twin.physics.fillet import FILLET_X, FILLET_Y
from twin.runs.metrics import metric_glossary

router = APIRouter(prefix="/api", tags=["furnace"])


def _lamp(name: str, cfg: FurnaceConfig) -> str:
    """'h3' -> 'h3', 'h-1' -> 'h14' (the last horizontal lamp), as numbered from x = 0."""
    side, _, index = name[0], name[1], name[1:]
    count = cfg.lamps.horizontal.count if side == "h" else cfg.lamps.vertical.count
    k = int(index)
    return f"{side}{k if k > 0 else count + 1 + k}"


def group_words(cfg: FurnaceConfig) -> dict[str, str]:
    """Each lamp group (thyristor channel) in words: which lamps it drives and where they are."""
    out = {}
    for g in cfg.lamps.groups:
        sides = {n[0] for n in g.lamps}
        where = ("horizontal lamps (across the specimen, spaced along its length x)" if sides == {"h"} else
                 "vertical lamps (along the specimen, spaced across its width y)" if sides == {"v"} else "lamps")
        out[g.name] = f"{g.name}: {where} {', '.join(_lamp(n, cfg) for n in g.lamps)}, driven together"
    return out


def glossary(cfg: FurnaceConfig) -> dict[str, Any]:
    s = cfg.specimen
    fx = f"{FILLET_X[0]:g}-{FILLET_X[1]:g} L_s x {FILLET_Y[0]:g}-{FILLET_Y[1]:g} W_s"
    mm = (1000 * (FILLET_X[1] - FILLET_X[0]) * s.length, 1000 * (FILLET_Y[1] - FILLET_Y[0]) * s.width)
    groups = group_words(cfg)
    terms = {
        "fillet": f"the region of interest in the middle of the specimen, {fx} ({mm[0]:.0f} x {mm[1]:.0f} mm; dashed "
                  "on the heat map). The fillet mean is its area average: the temperature the reference prescribes.",
        "t_E": "transition time: the reference goes from the initial fillet mean to the setpoint in t_E seconds "
               "(a smooth C1 curve) and stays there. The metric windows are measured in t_E.",
        "eta": "eta: the specimen's position along its length x. With oscillation on, the specimen moves as "
               "eta(t) = amplitude sin(2 pi t / period) past the lamps, which evens out the heating.",
        "u": "u: the power of each lamp group as a fraction of its maximum u_max (0 = off, 1 = full power): the "
             "feedforward u_ff plus the feedback correction, clipped to 0..1.",
        "u_ff": "u_ff: the feedforward powers planned in advance (an optimal-control solve) so that the model "
                "follows the reference; the feedback only corrects around them.",
        "groups": "lamp groups: the lamps are wired in six groups; each group has one power u. "
                  + " · ".join(groups.values()),
        "tc": "thermocouples: TC1-TC3 feed the estimator; TC4 (pink diamond) is only compared with the estimate "
              "(validation). Readings in K.",
        "tc4": "TC4: the validation thermocouple. The estimator never sees it, so reading - estimate there shows "
               "how good the estimated field is where nobody measures.",
        "T_sup": "T_sup (paper, section 5.1): the largest |estimated temperature - reference| over the fillet. It "
                 "includes the mean error; the metrics use it.",
        "spread": "spread: the largest |estimated temperature - fillet mean| over the fillet: the inhomogeneity "
                  "itself, without the mean error.",
        "windows": "metric windows: transient t0 .. t0 + t_E, steady t0 + 1.5 t_E .. t0 + 2 t_E, where t0 is the last "
                   "reference change (0 without one) and t_E, setpoint are that reference's. Errors in % are "
                   "relative to that setpoint.",
        "saturation": "a group at full power (100 %) cannot heat faster, a group off (0 %) cannot cool faster: the "
                      "controller has no headroom there. On the power chart each group has a lane above u = 1: a solid "
                      "bar while it is at full power, a pale one while it is off; the events say when (for spells "
                      "longer than a second at full power, a few seconds off).",
        "feasibility": "before a run (or a new reference) starts, the reference is simulated on the twin's model "
                       "with all lamps at full power and off: if the fillet mean cannot keep up, the page says when "
                       "and by how much; far beyond the furnace's ability, the start is refused.",
        "estimate": "the estimated field: the extended Kalman filter's temperature field from TC1-TC3 and the "
                    "model. No camera sees the specimen.",
        "mismatch": "plant mismatch: how much the simulated furnace deviates from the twin's model (relative, "
                    "0.05 = 5 % higher), to test robustness.",
        "speed": "speed: 'max' runs as fast as the computer can; a number is a real-time factor (2 = twice real time).",
        "estimator": "estimator: how the twin turns TC1-TC3 into the field. position-aware: the model at the "
                     "specimen's position eta(t) (the paper's EKF averages it over the oscillation period); "
                     "calibrating: it also learns lamp efficiency and emissivity while the reference holds. "
                     "The paper's: averaged, no calibration.",
        "shadow": "shadow estimator: a second estimator on the same TC readings and powers, only to compare; it "
                  "never drives the lamps. Its TC4 error and its field minus the estimate are charted beside "
                  "the first one's.",
        "calibration": "calibration: how much the furnace differs from the twin's model as the estimator learns "
                       "it, in % (-10 % = lamps 10 % weaker than the model); the band is +-1 standard deviation. "
                       "Effective values: they also absorb what the model gets wrong in other ways.",
        "plant": "the furnace of a run: simulated in process (any speed, its noise, seed, deviations and truth), or a "
                 "furnace over OPC UA (a real one, or furnace-twin emulate): real time on its clock, no truth, samples "
                 "that come late counted. The server connects only to the endpoints its settings allow.",
    }
    return {"metrics": metric_glossary(), "terms": terms,
            "groups": groups}


@router.get("/glossary")
def get_glossary(manager: ManagerDep) -> dict[str, Any]:
    """The metric names and the terms the dashboard explains, for the loaded furnace."""
    return glossary(manager.cfg)
