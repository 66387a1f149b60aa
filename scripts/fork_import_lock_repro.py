"""Reproduce the cold-start hang of issue 27 in a few seconds: ray-trace workers started while a thread of the
(multithreaded) parent is inside an import.

A thread imports a module whose body waits (in this process only) while the ray trace starts; the jobs import
the same module.  Workers forked from this process inherit the module's import lock held by a thread they do
not have, and wait forever (what gdb showed on the server, with ``scipy.optimize``); workers that are fresh
interpreters (``twin.radiation.workers``) import it themselves.

    python scripts/fork_import_lock_repro.py [--timeout 60]

Prints ``ok <seconds>`` and exits 0 when the trace finished, ``hung`` and exits 1 when it did not within the
timeout (the process then ends itself: a hung pool cannot be joined).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

SLOW = """import os, pathlib, time
if os.getpid() == {pid}:  # only the parent's import waits, holding the module's import lock
    while not pathlib.Path({flag!r}).exists():
        time.sleep(0.05)
"""
USER = """import numpy as np
def work(job):
    import slowmod_repro
    return np.full((2, 2), job[1]), "traced", False
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds before the trace counts as hung")
    args = ap.parse_args()
    d = Path(tempfile.mkdtemp(prefix="fork-import-lock-"))
    flag = d / "release"
    (d / "slowmod_repro.py").write_text(SLOW.format(pid=os.getpid(), flag=str(flag)))
    (d / "usesslow_repro.py").write_text(USER)
    sys.path.insert(0, str(d))
    os.environ["PYTHONPATH"] = os.pathsep.join([str(d), os.environ.get("PYTHONPATH", "")])

    import usesslow_repro

    from twin.radiation.exchange import run_positions

    holder = threading.Thread(target=__import__, args=("slowmod_repro",), daemon=True)
    holder.start()
    time.sleep(0.3)  # the thread is inside the module's body
    got: list[object] = []
    t0 = time.monotonic()
    trace = threading.Thread(target=lambda: got.append(
        run_positions(usesslow_repro.work, [(None, 1.0), (None, 2.0), (None, 3.0)], workers=2)), daemon=True)
    trace.start()
    trace.join(args.timeout)
    flag.touch()
    if not got:
        sys.stdout.write("hung\n")
        sys.stdout.flush()
        os._exit(1)  # a forked pool that hangs would keep the interpreter from exiting
    values = [float(F[0, 0]) for F in got[0]]  # type: ignore[attr-defined]
    if values != [1.0, 2.0, 3.0]:
        sys.stdout.write(f"wrong results {values}\n")
        return 1
    sys.stdout.write(f"ok {time.monotonic() - t0:.1f}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
