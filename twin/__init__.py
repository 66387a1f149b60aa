"""furnace-twin numerics: the simulated furnace, the reduced model, the EKF and the controller.

BLAS threads are set once, here.  Every matrix of the twin is small (at most 442 x 442) and a
running twin does numerics in several threads at once (closed loop, background re-planning,
3D view); on the 2-core machines it runs on, multi-threaded BLAS only contends (measured:
an EKF predict 30 ms instead of 0.3 ms, the terminal DARE 1.9 s instead of 0.07 s).  So the
package runs BLAS on one thread unless the user chose a thread count through the usual
environment variables.  Limits are not switched per call: changing the OpenBLAS thread count
from several threads at once is not thread-safe.
"""

from __future__ import annotations

import os
import sys

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
