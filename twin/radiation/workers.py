"""Ray-trace workers: fresh interpreters (``python -m twin.radiation.workers``) watched by a watchdog.

Why not a forked pool: the server is multithreaded; a child forked while another thread holds an import
lock (seen: a thread importing ``scipy.optimize``) inherits the held lock without its owner and blocks
forever on its first import of that module, so a cold start hung with 0 positions traced and no error.
A fresh interpreter imports everything itself, so no lock of the parent can reach it.

Protocol, over the worker's stdin / stdout (``multiprocessing.connection`` framing of pickles):
the parent sends ``(function, job)``, the worker answers ``("ok", result)`` or ``("error", text)``;
the worker's stray prints and its log go to its stderr, whose last lines explain a crash.

:func:`run_jobs` gives the jobs to up to ``workers`` such processes and raises :class:`TraceFailed` with
a reason when a worker dies, a job raises, or no worker used any CPU time for ``stall_s`` seconds
(a blocked worker; a slow one on a loaded machine still gets CPU time).  Each worker dies with the
process that started it (``PR_SET_PDEATHSIG``), so an orphan never holds the cache's lock file.
"""

from __future__ import annotations

import collections
import logging
import os
import pickle
import queue
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import IO, Any

log = logging.getLogger(__name__)

#: seconds without any CPU time used by a busy worker before the trace is reported as stalled
STALL_S = 60.0
#: lines of a worker's stderr kept to explain its end
STDERR_LINES = 20
_HEADER = 8  # bytes of the length prefix of a message


class TraceFailed(RuntimeError):
    """The ray trace could not finish; the message says why (a worker's error, exit or stall)."""


class TraceStalled(TraceFailed):
    """No worker made progress (CPU time) for ``stall_s`` seconds."""


def _send(stream: IO[bytes], obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(len(data).to_bytes(_HEADER, "little") + data)
    stream.flush()


def _recv(stream: IO[bytes]) -> Any:
    head = stream.read(_HEADER)
    if len(head) < _HEADER:
        raise EOFError("the worker closed its output")
    size = int.from_bytes(head, "little")
    data = stream.read(size)
    if len(data) < size:
        raise EOFError("the worker closed its output mid-message")
    return pickle.loads(data)


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU time (s) of process ``pid`` from ``/proc`` (Linux); ``None`` if unknown."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


class _Worker:
    """One worker process, fed one job at a time by its own thread."""

    def __init__(self, index: int) -> None:
        self.index = index
        env = dict(os.environ)
        env.setdefault("OMP_NUM_THREADS", "1")  # one core per worker, as the pool had
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "twin.radiation.workers", str(os.getpid())],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, close_fds=True,
        )
        self.stderr: collections.deque[str] = collections.deque(maxlen=STDERR_LINES)
        self.job: int | None = None  # index of the job in progress
        self.cpu = 0.0
        self.cpu_changed = time.monotonic()
        threading.Thread(target=self._drain_stderr, name=f"trace-worker-{index}-stderr", daemon=True).start()

    def _drain_stderr(self) -> None:
        assert self.proc.stderr is not None
        for line in iter(self.proc.stderr.readline, b""):
            self.stderr.append(line.decode(errors="replace").rstrip())

    def why_ended(self) -> str:
        code = self.proc.poll()
        tail = " | ".join(line for line in self.stderr if line.strip())[-600:]
        how = "is still running" if code is None else (f"was killed by signal {-code}" if code < 0
                                                       else f"exited with code {code}")
        return f"ray-trace worker {self.proc.pid} {how}" + (f": {tail}" if tail else "")

    def idle_for(self, now: float) -> float:
        """Seconds since this busy worker last used CPU time (0 if idle or unknown)."""
        if self.job is None:
            self.cpu_changed = now
            return 0.0
        cpu = cpu_seconds(self.proc.pid)
        if cpu is None or cpu != self.cpu:
            self.cpu = cpu if cpu is not None else self.cpu
            self.cpu_changed = now
        return now - self.cpu_changed

    def stop(self) -> None:
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.close()  # the worker's loop ends at EOF
            except OSError:
                pass
            try:
                self.proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def run_jobs(
    function: Callable[[Any], Any],
    jobs: Sequence[Any],
    *,
    workers: int,
    on_result: Callable[[int, Any], None] | None = None,
    stall_s: float = STALL_S,
    describe: Callable[[int], str] = lambda i: f"job {i + 1}",
) -> list[Any]:
    """``function(job)`` for every job in up to ``workers`` fresh interpreters; results in the order of ``jobs``.

    ``function`` must be importable by name (a module-level function).  ``on_result(i, result)`` is called
    in this thread as results arrive.  Raises :class:`TraceFailed` (a job's error, a worker's end) or
    :class:`TraceStalled` with the reason; every worker is ended before this returns or raises.
    """
    pending: queue.Queue[int] = queue.Queue()
    for i in range(len(jobs)):
        pending.put(i)
    results: queue.Queue[tuple[str, int, Any]] = queue.Queue()
    pool = [_Worker(k) for k in range(max(1, min(workers, len(jobs))))]

    def feed(w: _Worker) -> None:
        assert w.proc.stdin is not None and w.proc.stdout is not None
        try:
            while True:
                try:
                    i = pending.get_nowait()
                except queue.Empty:
                    return
                w.job = i
                _send(w.proc.stdin, (function, jobs[i]))
                status, value = _recv(w.proc.stdout)
                w.job = None
                results.put((status, i, value))
        except (EOFError, OSError, pickle.UnpicklingError):
            try:
                w.proc.wait(timeout=5.0)  # its exit code says how it ended
            except subprocess.TimeoutExpired:
                pass
            results.put(("died", w.job if w.job is not None else -1, w.why_ended()))

    out: dict[int, Any] = {}
    try:
        for w in pool:
            threading.Thread(target=feed, args=(w,), name=f"trace-worker-{w.index}", daemon=True).start()
        while len(out) < len(jobs):
            try:
                status, i, value = results.get(timeout=0.5)
            except queue.Empty:
                now = time.monotonic()
                for w in pool:
                    if w.job is not None and w.idle_for(now) > stall_s:
                        raise TraceStalled(
                            f"ray tracing stalled: worker {w.proc.pid} used no CPU time for {stall_s:.0f} s on "
                            f"{describe(w.job)} ({len(out)} of {len(jobs)} done)") from None
                continue
            if status == "ok":
                out[i] = value
                if on_result is not None:
                    on_result(i, value)
            elif status == "error":
                raise TraceFailed(f"ray tracing failed on {describe(i)}: {value}")
            else:
                where = f" on {describe(i)}" if i >= 0 else ""
                raise TraceFailed(f"ray tracing failed{where}: {value} ({len(out)} of {len(jobs)} done)")
    finally:
        for w in pool:
            w.stop()
    return [out[i] for i in range(len(jobs))]


def _die_with_parent(parent: int) -> None:
    """This worker gets SIGKILL when the process that started it ends (Linux ``PR_SET_PDEATHSIG``)."""
    try:
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):  # not Linux: the parent closes our stdin when it ends
        pass
    if os.getppid() != parent:
        os._exit(1)


def main(argv: list[str]) -> int:
    """The worker's loop: read ``(function, job)``, answer ``("ok", function(job))`` or ``("error", text)``."""
    if argv:
        _die_with_parent(int(argv[0]))
    # the protocol owns the real stdout; anything printed goes to stderr with the log
    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    source = sys.stdin.buffer
    while True:
        try:
            function, job = _recv(source)
        except EOFError:
            return 0
        try:
            reply: tuple[str, Any] = ("ok", function(job))
        except Exception as exc:  # the parent reports it as the trace's failure
            log.exception("ray-trace job failed")
            reply = ("error", f"{type(exc).__name__}: {exc}")
        _send(channel, reply)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
