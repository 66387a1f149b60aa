"""Which furnace parameters the three TCs can tell apart: the Fisher information of a default run.

Along the nominal model's feedforward run (heat-up over t_E, then the hold), the sensitivities
S_j = d theta_j / d p of the states to the calibration parameters p (lamp efficiency, emissivity,
convection; :class:`twin.model.tables.Parameters`) follow

    S_{j+1} = (dF/dtheta) S_j + dF/dp,     S_0 = 0                  (eqs. 12a, 16)

and the TCs y = C theta + v, v ~ N(0, r0 I), give the Fisher information
F = sum_j (C S_j)^T (C S_j) / r0.  Its inverse bounds the parameters' standard deviations (Cramer-Rao)
and its normalised form gives their correlations: two parameters the TCs cannot tell apart correlate
near +-1.  Split into the heat-up and the hold, it shows which pairs stay apart once the furnace holds
(where a slowly drifting parameter has to be tracked).  ``python scripts/observability.py
[--config banded]`` prints it (docs/estimation.md's choice of calibrated parameters comes from it).

Example
-------
>>> import numpy as np
>>> F = np.array([[4.0, 1.0], [1.0, 1.0]])
>>> float(round(correlations(F)[0, 1], 3))
-0.5
"""

from __future__ import annotations

import argparse
import sys
from itertools import combinations
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.model.tables import PARAMETERS

Array = NDArray[np.float64]


def correlations(F: Array) -> Array:
    """The correlation matrix of the parameter estimates whose Fisher information is F."""
    cov = np.linalg.inv(F)
    d = np.sqrt(np.diag(cov))
    return np.asarray(cov / np.outer(d, d))


def fisher_information(cfg: FurnaceConfig, radiation: Any, setpoint: float = 1100.0, t_E: float = 120.0,
                       duration: float = 240.0) -> dict[str, Array]:
    """F over the heat-up (t <= t_E), the hold and the whole run (3 x 3, order ``PARAMETERS``)."""
    from twin.control.feedforward import solve_feedforward
    from twin.control.reference import reference_trajectory
    from twin.model.discrete import discrete_model
    from twin.model.parametric import ParametricModel
    from twin.model.tables import model_tables
    from twin.scenario import TransitionReference

    tables = model_tables(cfg, radiation)
    T0 = cfg.specimen.initial_temperature
    ref = reference_trajectory(TransitionReference(setpoint=setpoint, t_E=t_E), T0)
    plan = solve_feedforward(discrete_model(cfg, radiation, tables=tables), np.full(tables.n, T0), 0.0, ref, cfg,
                             horizon=duration, best_effort=True)
    model = ParametricModel(tables, None, calibrated=PARAMETERS)
    C = model.fe.C(np.asarray(cfg.tc_positions()[:3]))
    theta, S = np.full(tables.n, T0), np.zeros((tables.n, len(PARAMETERS)))
    out = {k: np.zeros((len(PARAMETERS), len(PARAMETERS))) for k in ("heat-up", "hold", "whole run")}
    for j in range(plan.n_steps):
        u = plan.u_ff[j]
        S = model.jac_theta(theta, u) @ S + model.jac_p(theta, u)
        theta = model.step(theta, u)
        Y = C @ S
        info = Y.T @ Y / cfg.ekf.r0
        out["heat-up" if (j + 1) * cfg.sampling.t_s <= t_E else "hold"] += info
        out["whole run"] += info
    return out


def report(info: dict[str, Array]) -> str:
    """The correlations of each parameter pair (the others known) and the bounds, per phase, as text."""
    lines = []
    for phase, F in info.items():
        sd = np.sqrt(np.diag(np.linalg.inv(F)))
        lines.append(f"{phase}: Cramer-Rao sigma (all three estimated) "
                     + ", ".join(f"{n} {s:.2g}" for n, s in zip(PARAMETERS, sd, strict=True)))
        for i, j in combinations(range(len(PARAMETERS)), 2):
            r = correlations(F[np.ix_([i, j], [i, j])])[0, 1]
            lines.append(f"  {PARAMETERS[i]} + {PARAMETERS[j]}: correlation {r:+.3f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from twin.config import load_config
    from twin.radiation import radiation_model

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=None, help="furnace TOML file or a shipped furnace (default, banded)")
    args = parser.parse_args(argv)
    cfg = load_config(args.config)
    sys.stdout.write(report(fisher_information(cfg, radiation_model(cfg))) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
