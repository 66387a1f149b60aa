"""Ray-trace workers (twin/radiation/workers.py): fresh interpreters, never forks of a threaded server, and a
watchdog that says why a trace ended.

The first test is the cold-start hang of issue 27: the server forked its ray-trace pool while one of its threads
was importing a module (gdb: workers blocked on the import lock of ``scipy.optimize``).  scripts/
fork_import_lock_repro.py has a thread hold the import of a module whose body waits (in the parent only) while
the jobs import that module: a forked worker inherits the held module lock without its owner and waits forever
(the ``fork`` pool this replaced fails the test after 60 s); a fresh interpreter imports the module itself.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import uuid
from pathlib import Path
from types import ModuleType

import pytest

from twin.radiation.workers import TraceFailed, TraceStalled, run_jobs

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def helpers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Write modules into ``tmp_path`` (importable here and in the workers); returns ``make(name, source)``."""
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    made: list[str] = []

    def make(stem: str, source: str) -> str:
        name = f"{stem}_{uuid.uuid4().hex[:8]}"
        (tmp_path / f"{name}.py").write_text(source)
        made.append(name)
        return name

    yield make
    for name in made:
        sys.modules.pop(name, None)


def _import(name: str) -> ModuleType:
    import importlib

    return importlib.import_module(name)


def test_workers_start_while_a_thread_of_the_parent_holds_an_import_lock() -> None:
    # in its own process: a hung forked pool cannot be joined, and would keep pytest from exiting
    script = REPO / "scripts" / "fork_import_lock_repro.py"
    try:
        out = subprocess.run([sys.executable, str(script), "--timeout", "60"], capture_output=True, text=True,
                             timeout=180, cwd=REPO)
    except subprocess.TimeoutExpired:
        pytest.fail("the repro itself did not end")
    assert out.returncode == 0 and out.stdout.startswith("ok"), (out.stdout, out.stderr[-2000:])


def test_a_worker_that_uses_no_cpu_is_reported_as_stalled(helpers) -> None:
    mod = helpers("sleepy", "import time\ndef work(job):\n    time.sleep(600)\n")
    t0 = time.monotonic()
    with pytest.raises(TraceStalled, match=r"used no CPU time for 2 s on job 1 \(0 of 1 done\)"):
        run_jobs(_import(mod).work, [None], workers=1, stall_s=2.0)
    assert time.monotonic() - t0 < 30.0


def test_a_busy_worker_is_not_stalled(helpers) -> None:
    # a worker computing for longer than stall_s is slow, not stuck: it is waited for
    mod = helpers("busy", (
        "import time\n"
        "def work(job):\n"
        "    end = time.process_time() + job\n"
        "    while time.process_time() < end:\n"
        "        pass\n"
        "    return job\n"
    ))
    assert run_jobs(_import(mod).work, [3.0], workers=1, stall_s=1.0) == [3.0]


def test_a_job_that_raises_reports_its_error(helpers) -> None:
    mod = helpers("raises", "def work(job):\n    if job == 2:\n        raise ValueError('no rays left')\n"
                            "    return job\n")
    with pytest.raises(TraceFailed, match=r"on job 3: ValueError: no rays left"):
        run_jobs(_import(mod).work, [0, 1, 2], workers=2)


def test_a_worker_that_dies_reports_its_exit_and_last_words(helpers) -> None:
    mod = helpers("dies", (
        "import os, sys\n"
        "def work(job):\n"
        "    print('embree: out of memory', file=sys.stderr, flush=True)\n"
        "    os._exit(3)\n"
    ))
    with pytest.raises(TraceFailed, match=r"on job 1: ray-trace worker \d+ exited with code 3: embree: out of memory"):
        run_jobs(_import(mod).work, [0], workers=1)


def test_a_print_in_a_job_does_not_break_the_protocol(helpers) -> None:
    mod = helpers("chatty", "def work(job):\n    print('hello from', job)\n    return job * 2\n")
    assert run_jobs(_import(mod).work, [1, 2, 3], workers=2) == [2, 4, 6]
