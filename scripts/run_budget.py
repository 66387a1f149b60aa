"""The wall budget of one ``furnace-twin run``: where a user's wait goes (issue 21, ``docs/performance.md``).

``python scripts/run_budget.py [furnace-twin arguments]`` (default: ``run --out <tmp> --json``, the default
240 s run) runs the command of the checkout the script is in (``python <checkout>/scripts/run_budget.py`` for
another, e.g. a ``git archive`` of main) in this process with a timer around each part (imports, tables, the simulated
furnace, the first plan, the loop's steps, the rerun recording, the series' flushes, the final
``timeseries.npz``, the figures) and prints a markdown table: wall seconds, calls, share of the command.  The
command's own output goes to stderr.  Parts nest (the plan is inside building the loop, the recording's
``add`` inside the steps); the rows say which.  The interpreter's own start (about 0.1 s) is not in it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

_T0 = time.perf_counter()
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages, before an installed one

import contextlib  # noqa: E402
import functools  # noqa: E402
import importlib  # noqa: E402
import importlib.util  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from typing import Any  # noqa: E402

#: (module, attribute, label): the parts, in the order of a run; an indented label is inside the row above it
PARTS = (
    ("twin.radiation", "radiation_model", "radiation tables from the cache (the twin's model)"),
    ("twin.furnace.connect", "open_furnace", "the simulated furnace (its own table)"),
    ("twin.experiments.run", "ClosedLoop", "building the loop (model, estimator, controller, first plan)"),
    ("twin.runs.live_changes", "LiveChanges._plan", "  of which the first plan (OCP with IPOPT, LQG gains)"),
    ("twin.experiments.figures_process", "FigureProcess.__init__", "starting the figure process"),
    ("twin.runs.session", "RunSession.run", "the run (steps, flushes, final files)"),
    ("twin.runs.session", "RunSession.step", "  the loop's steps (with the recording's add)"),
    ("backend.storage.recording", "RecordingSink.add", "    of which the rerun recording's add"),
    ("twin.runs.session", "RunSession.flush", "  flushes: series parts appended, recording flushed"),
    ("twin.runs.folder", "RunFolder.write_timeseries", "  the final timeseries.npz (compressed, once)"),
    ("twin.runs.folder", "RunFolder.write_metrics", "  metrics.json"),
    ("twin.experiments.figures_process", "FigureProcess.draw", "figures: waiting for the figure process"),
    ("twin.experiments.figures", "plot_run", "figures: drawn in this process"),
)


#: the top-level parts running now: a top-level part called inside another (the truth's radiation table is loaded
#: with ``radiation_model`` inside ``open_furnace``) is that part's time, not counted twice
_RUNNING: list[str] = []


def _timed(acc: dict[str, list[float]], label: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    top = not label.startswith(" ")

    @functools.wraps(fn)
    def timed(*args: Any, **kwargs: Any) -> Any:
        if top and _RUNNING:
            return fn(*args, **kwargs)
        if top:
            _RUNNING.append(label)
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            acc.setdefault(label, []).append(time.perf_counter() - t)
            if top:
                _RUNNING.pop()

    return timed


def _wrap(acc: dict[str, list[float]], module: str, attr: str, label: str) -> None:
    """Time ``module.attr`` (a function or ``Class.method``) of a module the command has imported by now (the
    budget imports nothing the command would not); a part the code does not have is left out."""
    owner: Any = sys.modules.get(module)
    if owner is None:
        return
    *path, name = attr.split(".")
    for p in path:
        owner = getattr(owner, p, None)
    if owner is not None and hasattr(owner, name):
        setattr(owner, name, _timed(acc, label, getattr(owner, name)))


def budget(argv: Sequence[str]) -> tuple[int, list[tuple[str, int, float]], float]:
    """Run ``furnace-twin argv`` with the parts timed: (exit status, [(label, calls, seconds)], total seconds)."""
    acc: dict[str, list[float]] = {}
    t = time.perf_counter()
    import furnace_twin.cli as cli
    import twin.experiments.run  # noqa: F401  the run command's modules, as the command imports them
    import twin.furnace.connect  # noqa: F401
    import twin.radiation  # noqa: F401

    acc["imports: the CLI and the run command's modules"] = [time.perf_counter() - t]
    t = time.perf_counter()
    import backend.storage.recording  # noqa: F401

    acc["imports: the rerun recording (rerun)"] = [time.perf_counter() - t]
    if importlib.util.find_spec("twin.experiments.figures_process") is None:  # before issue 21: drawn here
        t = time.perf_counter()
        import twin.experiments.figures  # noqa: F401

        acc["imports: matplotlib and the figures (drawn in this process)"] = [time.perf_counter() - t]
    for module, attr, label in PARTS:
        _wrap(acc, module, attr, label)
    status = cli.main(list(argv))
    total = time.perf_counter() - _T0
    labels = [k for k in acc if k.startswith("imports")] + [label for _, _, label in PARTS if label in acc]
    return status, [(k, len(acc[k]), sum(acc[k])) for k in labels], total


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    with tempfile.TemporaryDirectory(prefix="furnace-twin-run-budget-") as d:
        if not args:
            args = ["run", "--out", d, "--json"]
        with contextlib.redirect_stdout(sys.stderr):  # the command's --json: not the table
            status, rows, total = budget(args)
    print("| part | wall s | calls | share |")  # noqa: T201
    print("|---|---|---|---|")  # noqa: T201
    for label, calls, seconds in rows:
        name = label.strip()
        indent = "&nbsp;&nbsp;" * ((len(label) - len(label.lstrip())) // 2)
        print(f"| {indent}{name} | {seconds:.2f} | {calls} | {100 * seconds / total:.0f} % |")  # noqa: T201
    print(f"| the whole command (after the interpreter's start) | {total:.2f} | | 100 % |")  # noqa: T201
    return status


if __name__ == "__main__":
    raise SystemExit(main())
