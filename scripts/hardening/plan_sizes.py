"""Finding 1: horizon, knots and the estimated size of plans for long transitions and short runs."""
import sys
from twin.config import load_config, small_config
from twin.radiation import radiation_model
from twin.model.discrete import discrete_model
from twin.control.reference import reference_trajectory
from twin.control.ocp_grid import plan_grid
from twin.scenario import TransitionReference
for name, cfg in (("default", load_config()), ("small", small_config())):
    model = discrete_model(cfg, radiation_model(cfg), None)
    for tE, dur in ((3600.0, 5.0), (3600.0, None), (120.0, 240.0), (600.0, 600.0), (3600.0, 3600.0)):
        ref = reference_trajectory(TransitionReference(setpoint=1100.0, t_E=tE), 300.0)
        g = plan_grid(model, ref, 0.0, cfg, t_stop=dur)
        e = g.estimate(model)
        print(f"{name:7s} t_E {tE:6.0f} s run {str(dur):6s}: horizon {g.horizon:6.0f} s, K {g.K:3d} knots of {g.interval:4.1f} s, n_heun {g.n_heun}, est. {e.memory_mb:6.0f} MB, {e.seconds:6.1f} s")
