"""A run's figures drawn by a child process, so that ``furnace-twin run`` does not wait for matplotlib's import.

Importing matplotlib and :mod:`twin.experiments.figures` costs about 1 s, drawing ``signals.png`` and
``field.png`` 1.2-1.9 s more (issue 21, a default 240 s run on a quiet 2-core machine), out of a 14.5 s
command.  ``furnace-twin run`` therefore starts a :class:`FigureProcess` before it loads anything: a
spawned process that imports the figure module while the twin plans and the loop steps (on another core).
Once the run's data is on disk (``timeseries.npz`` and ``metrics.json``,
:func:`twin.experiments.run.execute_run`), :meth:`FigureProcess.draw` hands it the folder; it reads
``timeseries.npz`` back and draws both figures there, and the command waits for them: when it returns, the
figures are there, as a lab user who opens the run's folder next expects (product.md lists them among a
run's files).  A figure that cannot be drawn is reported and costs the run nothing: its data is written
before.  ``--no-figures`` skips the process and the figures (scripts that only want the data).

The child is a fresh interpreter (``python -m twin.experiments.figures_process``, talking over its stdin and
stdout), not a fork: the parent may hold threads (rerun's, a re-planner's) that a fork would copy in an
unknown state, and unlike ``multiprocessing``'s spawn it does not re-run the caller's main script.  It runs in
a session of its own and ignores SIGINT: Ctrl-C at the terminal is the parent's, which ends it (closing its
stdin), so an interrupted run prints no traceback of it; a parent that dies closes that pipe as well.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import IO, Any

log = logging.getLogger(__name__)

#: How long :meth:`FigureProcess.draw` waits for both figures (s): drawing takes about 2 s on a quiet
#: machine, and the child's import before it about 1 s; a child that takes 40 times that is stuck, and is
#: ended: the run ends without its figures.
DRAW_TIMEOUT_S = 120.0
#: How long :meth:`FigureProcess.close` lets the child finish its import and exit before ending it (s).
CLOSE_TIMEOUT_S = 10.0


def serve(requests: IO[str], replies: IO[str]) -> None:
    """The child: import the figures (while the run goes), then draw the one run whose folder it is given
    (one line), if any, and reply one JSON line: ``{"figures": [paths]}`` or ``{"error": why}``."""
    from twin.experiments.figures import plot_run
    from twin.runs.folder import RunFolder
    from twin.runs.record import load_arrays

    out = requests.readline().strip()
    if not out:  # the parent closed the pipe: no run to draw
        return
    try:
        folder = RunFolder(Path(out))
        reply: dict[str, Any] = {"figures": [str(p) for p in plot_run(load_arrays(folder.timeseries), folder.folder)]}
    except Exception as exc:
        reply = {"error": f"{type(exc).__name__}: {exc}"}
    replies.write(json.dumps(reply) + "\n")
    replies.flush()


class FigureProcess:
    """One child process that draws one run's figures (module docstring).  Use it as a context manager."""

    def __init__(self) -> None:
        root = str(Path(__file__).resolve().parents[2])  # the checkout that holds twin: the child imports it
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
        self._child = subprocess.Popen(
            [sys.executable, "-m", "twin.experiments.figures_process"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, env=env, start_new_session=True,  # Ctrl-C at the terminal: the parent's
        )

    def draw(self, out: Path, timeout: float = DRAW_TIMEOUT_S) -> list[Path]:
        """Draw ``signals.png`` and ``field.png`` of the run in ``out`` (its ``timeseries.npz`` written) and
        wait for them; returns their paths, or none (logged why) if they could not be drawn."""
        stdin, stdout = self._child.stdin, self._child.stdout
        if stdin is None or stdout is None:  # Popen was given pipes: never
            raise RuntimeError("the figure process has no pipes")
        got: list[str] = []
        try:
            stdin.write(f"{Path(out).resolve()}\n")
            stdin.close()
            reader = threading.Thread(target=lambda: got.append(stdout.readline()), daemon=True)
            reader.start()
            reader.join(timeout)
        except OSError as exc:  # the child is gone (its exit code says how)
            got.append("")
            log.debug("the figure process: %s", exc)
        if not got:
            why = f"not done after {timeout:.0f} s"
        elif not got[0]:
            why = f"the figure process ended (exit code {self._child.poll()})"
        else:
            try:
                reply = json.loads(got[0])
            except ValueError:
                reply = {"error": f"an unreadable reply {got[0][:200]!r}"}
            if "figures" in reply:
                return [Path(p) for p in reply["figures"]]
            why = reply["error"]
        log.error("the run's figures were not drawn: %s; its data is in %s", why, out)
        return []

    def close(self) -> None:
        """Tell the child there is nothing (more) to draw, let it exit, end it if it does not; idempotent."""
        try:
            if self._child.stdin is not None and not self._child.stdin.closed:
                self._child.stdin.close()
        except OSError:  # a broken pipe: the child is gone
            pass
        try:
            self._child.wait(CLOSE_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self._child.kill()
            self._child.wait()
        if self._child.stdout is not None:
            self._child.stdout.close()

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    serve(sys.stdin, sys.stdout)
