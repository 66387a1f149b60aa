"""The run's estimators from the scenario's choice (``Scenario.estimator``, product.md).

``{"motion": "averaged", "calibrate": false}`` is the paper's EKF; ``position_aware`` predicts with
the model at the specimen's position eta(t_j); ``calibrate`` adds the furnace file's
``calibration.parameters`` to the state (:mod:`twin.estimation.joint`).  A shadow estimator is a
second one on the same TC data and inputs, for comparison only (it never drives the controller).

Example
-------
>>> from twin.config import small_config
>>> from twin.model.tables import model_tables
>>> from twin.radiation import radiation_model
>>> from twin.scenario import PAPER_ESTIMATOR
>>> cfg = small_config()
>>> est = build_estimator(PAPER_ESTIMATOR, model_tables(cfg, radiation_model(cfg)), None, cfg, 300.0)
>>> est.model.motion, est.model.calibrated, describe(PAPER_ESTIMATOR)
('averaged', (), 'averaged, no calibration')
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from twin.config import FurnaceConfig
from twin.estimation.joint import JointEstimator
from twin.model.parametric import ParametricModel
from twin.model.tables import ModelTables
from twin.scenario import EstimatorChoice, OscillationSpec


def estimator_model(choice: EstimatorChoice, tables: ModelTables, oscillation: OscillationSpec | None,
                    cfg: FurnaceConfig) -> ParametricModel:
    """The estimator's model for a choice: its motion, and the configured parameters if it calibrates."""
    osc = oscillation if oscillation is not None and oscillation.enabled else None
    calibrated = tuple(cfg.calibration.parameters) if choice.calibrate else ()
    return ParametricModel(tables, osc, motion=choice.motion, calibrated=calibrated,
                           heat_capacity=cfg.fe.heat_capacity)


def build_estimator(choice: EstimatorChoice, tables: ModelTables, oscillation: OscillationSpec | None,
                    cfg: FurnaceConfig, theta0: ArrayLike) -> JointEstimator:
    """A :class:`JointEstimator` for the choice, starting at theta0 with the nominal parameters."""
    return JointEstimator(estimator_model(choice, tables, oscillation, cfg), cfg, theta0)


def describe(choice: EstimatorChoice) -> str:
    """A short label, e.g. 'position-aware, calibrating'."""
    motion = "position-aware" if choice.motion == "position_aware" else "averaged"
    return f"{motion}, {'calibrating' if choice.calibrate else 'no calibration'}"
