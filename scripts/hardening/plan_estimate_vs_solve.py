"""Finding 1: the estimated plan time (one timed sweep) against the real solve, small furnace."""
import time, numpy as np
from twin.config import small_config
from twin.radiation import radiation_model
from twin.model.discrete import discrete_model
from twin.control.reference import reference_trajectory
from twin.control.ocp_grid import plan_grid
from twin.control.replan import replan
from twin.scenario import TransitionReference
cfg = small_config(); model = discrete_model(cfg, radiation_model(cfg), None)
for tE in (30.0, 120.0, 300.0):
    ref = reference_trajectory(TransitionReference(setpoint=1000.0, t_E=tE), 300.0)
    t = time.perf_counter()
    e = plan_grid(model, ref, 0.0, cfg).estimate(model, cfg, timed=True)
    est_took = time.perf_counter() - t
    t = time.perf_counter()
    plan, gains = replan(model, cfg, np.full(model.n, 300.0), 0.0, ref, best_effort=True)
    took = time.perf_counter() - t
    print(f"t_E {tE:5.0f}: K {e.knots} estimate {e.seconds:6.1f} s (made in {est_took:.1f} s), measured {took:6.1f} s "
          f"(ratio {took / e.seconds:4.2f}), sweeps {plan.warm['sweeps']}, est. {e.memory_mb:.0f} MB", flush=True)
