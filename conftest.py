"""Settings for every test and docstring example (pytest loads this before tests/ and twin/, backend/).

The test radiation cache (small_config's exchange factors, ray-traced once) and single-threaded
BLAS are set at import, so subprocesses and module-level code see them too.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parent
TEST_RADIATION_CACHE = REPO / ".cache" / "test-radiation"

os.environ["FURNACE_TWIN_CACHE"] = str(TEST_RADIATION_CACHE)
# The suite runs on 2 shared cores with 2 xdist workers: multi-threaded BLAS only contends
# (a 442 x 442 solve took 10x longer with threads under load).  The environment variables
# work if numpy is not imported yet; tests/conftest.py limits already-loaded libraries.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# --doctest-modules would import the test folders' conftest.py files as doctest modules named
# "conftest", clashing with the ones the tests import; they hold no examples.
collect_ignore_glob = ["tests/**/conftest.py", "tests/conftest.py"]
