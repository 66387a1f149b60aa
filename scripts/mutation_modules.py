"""Mutation testing that counts every mutant: per module, cached by source hash, one score over all.

A separate command (not part of CI: a module costs minutes to an hour on the shared 2-core machine)::

    .venv/bin/python scripts/mutation_modules.py twin.runs.metrics twin.estimation.glr   # run these modules
    .venv/bin/python scripts/mutation_modules.py --all          # every module of the scope (hours)
    .venv/bin/python scripts/mutation_modules.py --summary docs/mutation.md --report test-artifacts/mutation-report.md

Each module is run with mutmut (settings in ``[tool.mutmut]`` of pyproject.toml: the scope's modules and the
fast tests that cover them) and its result stored in ``.mutation-cache/<module>.json`` with the SHA-256 of
the module's source, the sources of the test files that covered it in that run (mutmut's stats) and the mutmut
settings other than the selection: a module whose hash is unchanged is not run again; one whose code or covering
tests changed is.  A test added to the selection stales only the modules it was covering in their runs, so one
more test file no longer stales every result (before stop 36 every selected test was in every fingerprint); a
new test that would cover a module leaves its result a lower bound until it is run again (``--force``).

The score counts every mutant of the module: ``raw = (killed + timeout) / mutants``.  A mutant the run
never reached counts as not detected ("not run"), a module never run is listed as "not run".  There are no
rules that excuse a class of edits: a survivor is equivalent only if ``scripts/mutation_equivalent.toml``
names it (``[mutant."name"]``) with a ``reason`` and a ``second_look`` (who checked the reason, and how);
``score = (killed + timeout) / (mutants - equivalent)`` is given beside the raw one.  The older
``[[rule]]`` entries of that file (issue 17) are ignored here.

The summary (``--summary``) is a short table; the full report (``--report``: every mutant not killed with
its diff) is an artifact, not committed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import logging
import os
import subprocess
import sys
import tomllib
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".mutation-cache"
EQUIVALENT_FILE = ROOT / "scripts" / "mutation_equivalent.toml"
log = logging.getLogger("mutation")

#: mutmut exit codes -> status (mutmut.stats.status_by_exit_code)
STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests", 36: "timeout", 24: "timeout",
          -24: "timeout", 152: "timeout", 255: "timeout", 34: "skipped", 37: "type check", None: "not run"}

#: module -> why it is in scope (issue 17's numerics; issue 23 added the estimators, the parametric model,
#: the fault detection, the OCP set-up, shooting, feasibility and the plant)
SCOPE: dict[str, str] = {
    "twin.runs.metrics": "metrics of product.md",
    "twin.estimation.ekf": "EKF predict / update",
    "twin.estimation.joint": "joint (calibrating) EKF",
    "twin.estimation.glr": "GLR fault tests",
    "twin.estimation.fault_detection": "fault detector",
    "twin.model.parametric": "parametric model (calibrated parameters)",
    "twin.control.reference": "reference trajectories",
    "twin.control.lqg": "LQG gains",
    "twin.control.plan": "plans",
    "twin.control.ocp_grid": "OCP grid",
    "twin.control.feedforward": "OCP set-up (each mutant: an IPOPT solve)",
    "twin.control.shooting": "multiple shooting",
    "twin.control.feasibility": "feasibility check",
    "twin.model.averaging": "time-averaged model",
    "twin.model.fe": "FE model",
    "twin.model.discrete": "discrete model and Jacobian",
    "twin.physics.motion": "eta(t)",
    "twin.physics.fillet": "fillet",
    "twin.furnace.simulated.thermocouples": "TC dynamics",
    "twin.furnace.simulated.integrators": "plant integrators",
    "twin.furnace.simulated.plant": "plant",
    "twin.furnace.simulated.conduction": "plant conduction",
    "twin.furnace.simulated.radiative_source": "plant radiative source",
}


def source_of(module: str) -> Path:
    return ROOT / (module.replace(".", "/") + ".py")


def _read_tree(path: str) -> bytes | None:
    """A file of the working tree (relative to the repository), None if there is none."""
    f = ROOT / path
    return f.read_bytes() if f.is_file() else None


def _mutmut_settings(read: Callable[[str], bytes | None] = _read_tree) -> dict[str, Any]:
    return tomllib.loads((read("pyproject.toml") or b"").decode())["tool"]["mutmut"]


SELECTION = "pytest_add_cli_args_test_selection"


def fingerprint(module: str, tests: list[str] | None = None,
                read: Callable[[str], bytes | None] = _read_tree) -> str:
    """SHA-256 of the module's source, the sources of ``tests`` (the test files that covered the module in its
    run, :func:`covering_tests`) and the mutmut settings other than the selection itself.  ``tests=None``: the
    rule before stop 36, every selected test's source and the whole settings (a result stored then stays current
    under it until it is run again).  ``read`` gives a file's bytes (the tree's; :func:`revalidate`: a commit's)."""
    settings = _mutmut_settings(read)
    h = hashlib.sha256(read(str(source_of(module).relative_to(ROOT))) or b"")
    if tests is None:
        names = sorted(settings.get(SELECTION, []))
    else:
        names = sorted(tests)
        settings = {k: v for k, v in settings.items() if k != SELECTION}
    for test in names:
        h.update(test.encode())
        h.update(read(test.split("::")[0]) or b"")
    h.update(json.dumps(settings, sort_keys=True).encode())
    return h.hexdigest()


def covering_tests(module: str, stats: Path | None = None) -> list[str] | None:
    """The test files that cover ``module``'s functions, from mutmut's stats of its last run (the tests mutmut runs
    against each mutant); None if the stats do not know the module."""
    stats = stats or ROOT / "mutants" / "mutmut-stats.json"
    if not stats.is_file():
        return None
    by_function = json.loads(stats.read_text()).get("tests_by_mangled_function_name", {})
    mine = [tests for name, tests in by_function.items() if name.startswith(f"{module}.x")]
    if not mine:
        return None
    return sorted({t.split("::")[0] for tests in mine for t in tests})


def _cache_file(module: str) -> Path:
    return CACHE / f"{module}.json"


def cached(module: str) -> dict[str, Any] | None:
    """The stored result of ``module`` if its fingerprint still matches: its source, the tests that covered it
    and the settings unchanged.  A test file added to the selection that would cover it does not stale it: the
    result is then a lower bound until the module is run again (``--force``)."""
    f = _cache_file(module)
    if not f.is_file():
        return None
    data = json.loads(f.read_text())
    return data if data.get("fingerprint") == fingerprint(module, data.get("tests")) else None


def _git_show(commit: str, path: str) -> bytes | None:
    done = subprocess.run(["git", "show", f"{commit}:{path}"], cwd=ROOT, capture_output=True, check=False)
    return done.stdout if done.returncode == 0 else None


def _stamp(module: str, data: dict[str, Any], tests: list[str], **extra: str) -> None:
    """Store ``data`` with the per-module fingerprint of its covering ``tests``."""
    data.update(tests=tests, fingerprint=fingerprint(module, tests), **extra)
    _cache_file(module).write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")


def revalidate(module: str, commit: str) -> bool:
    """A stale result made on ``commit`` under the rule before stop 36 that still holds: its old fingerprint is
    the one computed from ``commit``'s files (so it was measured on them), the module's source is the same at
    ``commit`` as in the tree, and every test file that covers it now (mutmut's stats) was selected whole at
    ``commit`` and is the same.  Such a result gets the per-module fingerprint; True if it was rewritten."""
    f = _cache_file(module)
    if not f.is_file():
        return False
    data = json.loads(f.read_text())
    if "tests" in data or cached(module) is not None:
        return False

    def then(path: str) -> bytes | None:
        return _git_show(commit, path)

    src = str(source_of(module).relative_to(ROOT))
    if then("pyproject.toml") is None or then(src) is None or then(src) != _read_tree(src):
        return False
    tests = covering_tests(module)
    if fingerprint(module, read=then) != data.get("fingerprint") or tests is None:
        return False
    selected_then = {t for t in _mutmut_settings(then).get(SELECTION, []) if "::" not in t}  # whole files
    if any(t not in selected_then or then(t) != _read_tree(t) for t in tests):
        return False  # a covering test that was not run then (or differs): the result may be lower now
    _stamp(module, data, tests, revalidated=f"on {commit}")
    return True


def migrate(module: str) -> bool:
    """A result stored under the rule before stop 36 (no ``tests``) that is still current under it gets its
    covering tests (from mutmut's stats) and the per-module fingerprint; True if it was rewritten."""
    f = _cache_file(module)
    if not f.is_file():
        return False
    data = json.loads(f.read_text())
    if "tests" in data or data.get("fingerprint") != fingerprint(module):
        return False
    tests = covering_tests(module)
    if tests is None:
        return False
    _stamp(module, data, tests)
    return True


def _results(module: str) -> dict[str, str]:
    """mutant name -> status, from mutmut's ./mutants for one module (every mutant it generated)."""
    meta = ROOT / "mutants" / (module.replace(".", "/") + ".py.meta")
    if not meta.is_file():
        return {}
    data = json.loads(meta.read_text())
    return {name: STATUS.get(code, f"exit {code}") for name, code in data.get("exit_code_by_key", {}).items()}


def _diff(name: str, module: str) -> str:
    os.chdir(ROOT)
    from mutmut.mutation.diff_apply import get_diff_for_mutant

    try:
        return get_diff_for_mutant(name, path=module.replace(".", "/") + ".py").strip()
    except Exception as exc:  # noqa: BLE001  (a report line, not a crash)
        return f"(no diff: {exc})"


def run_module(module: str, *, children: int = 2) -> dict[str, Any]:
    """Run every mutant of ``module`` (niced) and store the result with its fingerprint."""
    if str(source_of(module).relative_to(ROOT)) not in _mutmut_settings().get("only_mutate", []):
        raise SystemExit(f"{module}: add {source_of(module).relative_to(ROOT)} to [tool.mutmut] only_mutate")
    started = dt.datetime.now(dt.UTC)
    cmd = ["nice", "-n", "19", str(ROOT / ".venv" / "bin" / "mutmut"), "run", "--max-children", str(children),
           f"{module}.*"]
    log.info("running %s", " ".join(cmd))
    done = subprocess.run(cmd, cwd=ROOT, env={**os.environ, "MPLBACKEND": "Agg", "OPENBLAS_NUM_THREADS": "1"},
                          check=False)
    results = _results(module)
    tests = covering_tests(module) or []
    data = {"module": module, "tests": tests, "fingerprint": fingerprint(module, tests),
            "date": started.isoformat(timespec="seconds"),
            "wall_s": round((dt.datetime.now(dt.UTC) - started).total_seconds()), "mutmut_exit": done.returncode,
            "results": results,
            "diffs": {n: _diff(n, module) for n, st in results.items() if st not in ("killed", "timeout")}}
    CACHE.mkdir(exist_ok=True)
    _cache_file(module).write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    return data


def equivalents() -> dict[str, dict[str, Any]]:
    """The per-mutant equivalence entries that carry a reason and a second look."""
    if not EQUIVALENT_FILE.is_file():
        return {}
    entries = tomllib.loads(EQUIVALENT_FILE.read_text()).get("mutant", {})
    return {n: e for n, e in entries.items() if e.get("reason") and e.get("second_look")}


def counts(data: dict[str, Any], eq: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Killed, timeout, survived, no tests, not run, equivalent; raw score and score (over every mutant)."""
    res = data["results"]
    c = Counter(res.values())
    n = len(res)
    detected = c["killed"] + c["timeout"]
    equivalent = sum(1 for name, st in res.items() if st not in ("killed", "timeout") and name in eq)
    other = n - detected - c["survived"] - c["no tests"] - c["not run"]
    return {"mutants": n, "killed": c["killed"], "timeout": c["timeout"], "survived": c["survived"],
            "no tests": c["no tests"], "not run": c["not run"] + other, "equivalent": equivalent,
            "raw": detected / n if n else float("nan"),
            "score": detected / (n - equivalent) if n > equivalent else float("nan")}


NOTES = "\n## Notes"
SUMMARY_HEAD = """# Mutation testing

Written by `bash scripts/mutation.sh MODULE...` (`scripts/mutation_modules.py`; mutmut with the settings of
`[tool.mutmut]` in pyproject.toml).  Each module's result is cached under the SHA-256 of its source, the test
files that covered it in its run and the settings, and listed here with its date and hash; a module whose code or
covering tests changed since is marked "stale" (its row as measured then, not in the total) until it is run again.
Every mutant counts: raw score = (killed + timeout) / mutants; a mutant the run never reached is "not run" and
counts as not detected.  A survivor is equivalent only when `scripts/mutation_equivalent.toml` names it (a
`[mutant."name"]` entry) with a reason and a second look; the issue-17 regex rules are not applied.  The full
report with every survivor's diff is an artifact (`test-artifacts/mutation-report.md`), not committed.

"""


def summary(modules: list[str]) -> str:
    """The table: a row per module with a result; a result whose module or selected tests changed since its run
    is shown as it was measured, marked stale, and left out of the total (the total counts current results)."""
    eq = equivalents()
    head = ("| module | mutants | killed | timeout | survived | no tests | not run | equivalent | raw score "
            "| date | source hash |")
    rows = [head, "| --- " * 11 + "|"]
    tot: Counter[str] = Counter()
    not_run, stale = [], []
    for module in modules:
        data = cached(module)
        current = data is not None
        if not current and _cache_file(module).is_file():  # measured on other code or tests: shown, marked
            data = json.loads(_cache_file(module).read_text())
            stale.append(module)
        if data is None:
            not_run.append(module)
            continue
        k = counts(data, eq)
        if current:
            for key in ("mutants", "killed", "timeout", "survived", "no tests", "not run", "equivalent"):
                tot[key] += k[key]
        rows.append(f"| {module} | {k['mutants']} | {k['killed']} | {k['timeout']} | {k['survived']} | "
                    f"{k['no tests']} | {k['not run']} | {k['equivalent']} | {100 * k['raw']:.1f} % | "
                    f"{data['date'][:10]}{'' if current else ' (stale)'} | {data['fingerprint'][:12]} |")
    if tot["mutants"]:
        raw = (tot["killed"] + tot["timeout"]) / tot["mutants"]
        rows.append(f"| **current results** | {tot['mutants']} | {tot['killed']} | {tot['timeout']} | "
                    f"{tot['survived']} | {tot['no tests']} | {tot['not run']} | {tot['equivalent']} | "
                    f"**{100 * raw:.1f} %** | | |")
    lines = [*rows, ""]
    if stale:
        lines += ["Stale (the module's source or a test that covered it changed since its run, or the result was "
                  "made under the rule before stop 36 with other tests selected: the row is the result as measured "
                  "then, not in the total):", ""]
        lines += [f"- {m}" for m in stale] + [""]
    if not_run:
        lines += ["Not run (no result; their mutants are not in the total):", ""]
        lines += [f"- {m}" for m in not_run] + [""]
    return "\n".join(lines)


def full_report(modules: list[str]) -> str:
    eq = equivalents()
    out = ["# Mutation report (every mutant not killed, with its diff)", "", summary(modules), ""]
    for module in modules:
        data = cached(module)
        if data is None:
            continue
        for name, d in sorted(data["diffs"].items()):
            st = data["results"][name]
            note = eq.get(name)
            out += [f"#### `{name}`: {st}" + (" (equivalent)" if note else ""), "", "```diff", d, "```", ""]
            if note:
                out += [f"Equivalent: {note['reason']} (second look: {note['second_look']})", ""]
    return "\n".join(out)


def main() -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help="modules to run (skipped when their cached result is current)")
    ap.add_argument("--all", action="store_true", help="every module of the scope")
    ap.add_argument("--force", action="store_true", help="run even if the cached result is current")
    ap.add_argument("--list", action="store_true", help="the scope, and which modules have a current result")
    ap.add_argument("--revalidate", metavar="COMMIT", help="keep stale results made on COMMIT (the rule before "
                    "stop 36) whose module and covering tests are unchanged since")
    ap.add_argument("--summary", type=Path, help="write the short summary table (markdown) here")
    ap.add_argument("--report", type=Path, help="write the full report (every survivor's diff) here")
    a = ap.parse_args()
    unknown = [m for m in a.modules if m not in SCOPE]
    if unknown:
        ap.error(f"not in the scope: {', '.join(unknown)} (see --list)")
    for module in SCOPE if a.revalidate else []:
        if revalidate(module, a.revalidate):
            log.info("%s: result of %s kept (module and covering tests unchanged since)", module, a.revalidate)
    for module in SCOPE:  # results stored under the old rule, still current under it: per-module fingerprints
        if migrate(module):
            log.info("%s: result kept, fingerprinted by the %d test files that covered it", module,
                     len(json.loads(_cache_file(module).read_text())["tests"]))
    for module in (list(SCOPE) if a.all else a.modules):
        if not a.force and cached(module) is not None:
            log.info("%s: current result cached, not run", module)
            continue
        run_module(module)
    if a.list:
        for module, why in SCOPE.items():
            state = "current" if cached(module) else ("stale" if _cache_file(module).is_file() else "not run")
            sys.stdout.write(f"{module:42s} {state:8s} {why}\n")
    if a.summary:  # the generated table; a "## Notes" section written by hand below it is kept
        notes = ""
        if a.summary.is_file() and NOTES in a.summary.read_text():
            notes = NOTES + a.summary.read_text().split(NOTES, 1)[1]
        a.summary.write_text(SUMMARY_HEAD + summary(list(SCOPE)) + notes)
    if a.report:
        a.report.parent.mkdir(parents=True, exist_ok=True)
        a.report.write_text(full_report(list(SCOPE)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
