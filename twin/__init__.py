"""furnace-twin numerics: the simulated furnace, the reduced model, the EKF and the controller.

The names a script needs are here (:data:`__all__`), imported when first used (``import twin`` stays cheap).
A run in four lines, on the small test furnace (``examples/`` has more)::

    >>> import twin
    >>> cfg = twin.small_config()
    >>> scenario = twin.parse_scenario({"reference": {"points": [[0, 300], [0.4, 310]]}, "duration": 0.5})
    >>> result = twin.RunSession(twin.ClosedLoop(cfg, scenario)).run()
    >>> result["status"], sorted(twin.__all__)[:3]
    ('finished', ['ClosedLoop', 'FurnaceConfig', 'RunFolder'])

BLAS threads are set once, here.  Every matrix of the twin is small (at most 442 x 442) and a
running twin does numerics in several threads at once (closed loop, background re-planning,
3D view); on the 2-core machines it runs on, multi-threaded BLAS only contends (measured:
an EKF predict 30 ms instead of 0.3 ms, the terminal DARE 1.9 s instead of 0.07 s).  So the
package runs BLAS on one thread unless the user chose a thread count through the usual
environment variables.  Limits are not switched per call: changing the OpenBLAS thread count
from several threads at once is not thread-safe.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.config import FurnaceConfig, load_config, small_config
    from twin.estimation.choice import build_estimator
    from twin.experiments.campaign import campaign_scenarios, run_campaign
    from twin.experiments.run import execute_run
    from twin.model.tables import model_tables
    from twin.radiation import radiation_model
    from twin.runs.folder import RunFolder
    from twin.runs.loop import ClosedLoop
    from twin.runs.metrics import run_metrics
    from twin.runs.record import load_arrays
    from twin.runs.session import RunSession
    from twin.scenario import Scenario, parse_scenario

#: the public names and the module each comes from
_PUBLIC = {
    "FurnaceConfig": "twin.config", "load_config": "twin.config", "small_config": "twin.config",
    "Scenario": "twin.scenario", "parse_scenario": "twin.scenario",
    "radiation_model": "twin.radiation", "model_tables": "twin.model.tables",
    "ClosedLoop": "twin.runs.loop", "RunSession": "twin.runs.session", "RunFolder": "twin.runs.folder",
    "load_arrays": "twin.runs.record", "run_metrics": "twin.runs.metrics",
    "build_estimator": "twin.estimation.choice",
    "execute_run": "twin.experiments.run", "campaign_scenarios": "twin.experiments.campaign",
    "run_campaign": "twin.experiments.campaign",
}
__all__ = [
    "ClosedLoop",
    "FurnaceConfig",
    "RunFolder",
    "RunSession",
    "Scenario",
    "build_estimator",
    "campaign_scenarios",
    "execute_run",
    "load_arrays",
    "load_config",
    "model_tables",
    "parse_scenario",
    "radiation_model",
    "run_campaign",
    "run_metrics",
    "small_config",
]


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use."""
    if name not in _PUBLIC:
        raise AttributeError(f"module 'twin' has no attribute {name!r}")
    value = getattr(importlib.import_module(_PUBLIC[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])

_BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _single_threaded_blas() -> None:
    if any(v in os.environ for v in _BLAS_THREAD_VARS):
        return  # the user (or the test suite) decided
    for v in _BLAS_THREAD_VARS:
        os.environ[v] = "1"  # effective for numpy imported after this point and for subprocesses
    if "numpy" in sys.modules:  # numpy already loaded its BLAS: limit the running pools once
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")


_single_threaded_blas()
