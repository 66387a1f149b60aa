"""Finding 2: the estimate vs the plant across TC noise levels (small furnace, 40 s runs to 1000 K, seeds 0, 1).
Usage: python noise_probe.py 2 5 10   (noise levels in K; beyond twin.limits the scenario is built unchecked)"""
import sys, time, logging
import numpy as np
from twin.config import small_config
from twin.radiation import radiation_model
from twin.runs.loop import ClosedLoop
from twin.scenario import Scenario
cfg = small_config(); rad = radiation_model(cfg)
plans = {}
for noise in [float(x) for x in sys.argv[1:]]:
    for seed in (0, 1):
        sc = Scenario.model_validate({"reference": {"setpoint": 1000.0, "t_E": 20.0}, "duration": 40.0, "seed": seed})
        sc = sc.model_copy(update={"tc_noise": noise})  # unchecked: beyond the scenario's limit on purpose
        loop = ClosedLoop(cfg, sc, rad, plan_cache=plans)
        worst, msg = 0.0, "ok"
        try:
            for s in loop.run():
                err = abs(s.T_mean_hat - s.true_mean)
                if not np.isfinite(err) or err > 1e4:
                    msg = f"diverged at t={s.t:.1f}: T_mean_hat={s.T_mean_hat:.3g}"; break
                worst = max(worst, err)
        except Exception as e:
            msg = f"{type(e).__name__}: {e}"
        print(f"noise {noise:5.1f} seed {seed}: max |mean_hat - true| {worst:8.2f} K  {msg}", flush=True)
