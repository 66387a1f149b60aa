"""The twin's own model against the truth, open loop: how far is the model from the furnace it stands for?

The paper's identified model was within 4.4 % of its furnace (section 2.4).  Here the discrete model
of the twin (eq. 12a; time averaged, eq. 11, when the specimen oscillates) is driven by the inputs a
run applied to the simulated furnace, from the furnace's initial field, with no estimator, and its
field is compared with the furnace's true field (both on the FD cells, relative to the setpoint):

* ``model_mean_error_{transient,steady}_max``: max |fillet mean of the model - of the truth|;
* ``model_point_error_{transient,steady}_max``: max over the fillet's cells |model - truth|,

in the windows of :func:`twin.runs.metrics.window` (transient 0..t_E, steady 1.5..2 t_E).  Against
``"truth": "shared"`` this is the model reduction alone (FE grid, constant c_p, averaging); against
the independent truth it is what a real furnace would show.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.physics.grid import cell_centers
>>> from twin.radiation import radiation_model
>>> from twin.scenario import Scenario
>>> cfg = small_config(); x, y = cell_centers(cfg)
>>> ts = {"t": np.arange(3) * 0.1, "u": np.zeros((3, 6)), "t_field": np.arange(3) * 0.1, "x": x, "y": y,
...       "field_true": np.full((3, 17, 26), 300.0), "setpoint": 1100.0, "t_E": 0.1, "L_s": 0.4, "W_s": 0.2,
...       "scenario": Scenario().to_json()}
>>> e = open_loop_model_error(cfg, ts, radiation_model(cfg))
>>> sorted(e) == sorted(MODEL_ERROR_KEYS), e["model_mean_error_transient_max"] < 1e-3   # the cold plate cools little
(True, True)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from twin.config import FurnaceConfig
from twin.physics.fillet import Fillet
from twin.runs.metrics import window
from twin.scenario import Scenario

MODEL_ERROR_KEYS = (
    "model_mean_error_transient_max",
    "model_mean_error_steady_max",
    "model_point_error_transient_max",
    "model_point_error_steady_max",
)


def _max(v: np.ndarray, sel: np.ndarray) -> float:
    v = v[sel]
    return float(np.max(v)) if v.size else float("nan")


def open_loop_model_error(cfg: FurnaceConfig, ts: Mapping[str, Any], radiation: Any) -> dict[str, float]:
    """The model driven by a run's inputs ``u`` against its true field (see the module docstring).

    ``ts`` is a run's time series (``timeseries.npz`` layout, with ``field_true``); ``radiation`` the
    twin's radiation model.  The oscillation is the scenario's (a run without live changes).
    """
    from twin.model.discrete import discrete_model

    scenario = Scenario.model_validate_json(str(ts["scenario"]))
    osc = scenario.oscillation
    model = discrete_model(cfg, radiation, osc if osc.enabled else None)
    t = np.asarray(ts["t"], float)
    u = np.asarray(ts["u"], float)
    tf = np.asarray(ts["t_field"], float)
    true = np.asarray(ts["field_true"], float)
    Mt = model.M_theta
    theta = np.linalg.lstsq(Mt, true[0].ravel(), rcond=None)[0]  # the furnace's initial field on the FE nodes
    thetas = np.empty((len(t), model.n))
    for j in range(len(t)):
        thetas[j] = theta
        theta = model.step(theta, u[j])
    at = np.clip(np.searchsorted(t, tf - 1e-9), 0, len(t) - 1)  # the samples of the stored fields
    field = (thetas[at] @ Mt.T).reshape(true.shape)
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    scale = float(ts["setpoint"])
    mean_err = np.abs(fillet.mean(field) - fillet.mean(true)) / scale
    point_err = np.max(np.abs(field - true)[..., fillet.mask], axis=-1) / scale
    t_E = float(ts["t_E"])
    tr, st = window(tf, t_E, "transient"), window(tf, t_E, "steady")
    return {
        "model_mean_error_transient_max": _max(mean_err, tr),
        "model_mean_error_steady_max": _max(mean_err, st),
        "model_point_error_transient_max": _max(point_err, tr),
        "model_point_error_steady_max": _max(point_err, st),
    }
