"""Scope and report of the mutation runs of the numerics (``scripts/mutation.sh``, issue 17).

``--scope`` prints the mutmut name globs of what is mutated; ``--not-killed`` the names of the
mutants that survived (or timed out, or had no test) in ./mutants; ``--out FILE`` writes the
report: per module killed / survived / timeout / no tests / score, and every mutant that was not
killed with its diff and, if it is listed in ``scripts/mutation_equivalent.toml``, why it is
equivalent (no test can tell it from the original).

Score = detected / (checked - equivalent), detected = killed + timeout (a mutant that hangs the
tests is caught by the suite's time limits too), checked = the mutants the run reached.  The raw
score (equivalents counted as survivors) is given beside it.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tomllib
from collections import Counter
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EQUIVALENT_FILE = ROOT / "scripts" / "mutation_equivalent.toml"

#: module -> None (every function) or the functions in scope.  Out of scope: the IPOPT set-up of
#: the feedforward OCP (twin.control.feedforward: _solve_feedforward, solve_feedforward, _ipopt_options:
#: each mutant is a 40 s OCP solve, tested by tests/control/test_feedforward.py, and issue 15 rewrites
#: it) and the benchmark helpers (ocp_seconds, ekf_step_ms: timing loops, judged by `furnace-twin bench`).
#: The OCP grid's scanned functions moved from twin.control.feedforward to twin.control.ocp_grid (issue 9).
SCOPE: dict[str, list[str] | None] = {
    "twin.runs.metrics": None,
    "twin.estimation.ekf": ["x_process_noise", "x_propagate_covariance", "x_ekf_predict", "x__gain", "x_ekf_update",
                            "xǁEstimatorǁ"],
    "twin.control.reference": None,
    "twin.control.lqg": None,
    "twin.control.plan": None,
    "twin.control.ocp_grid": ["x_transition_end", "x_mean_time_constant", "x__fastest_rate"],
    "twin.model.averaging": None,
    "twin.physics.motion": None,
    "twin.physics.fillet": None,
    "twin.furnace.simulated.thermocouples": None,
    "twin.model.fe": None,
    "twin.model.discrete": None,
    "twin.furnace.simulated.integrators": None,
}

#: modules other work will rewrite: their survivors (and equivalence notes) need a fresh look then
LIKELY_TO_CHANGE = {
    "twin.estimation.ekf": "issue 11 (self-calibrating, position-aware estimator)",
    "twin.control.ocp_grid": "issue 15 (bounded planning horizons)",
    "twin.control.plan": "issue 15 (bounded planning horizons)",
    "twin.control.lqg": "issue 15 (gains along bounded horizons)",
}

#: mutmut exit codes -> status (mutmut.stats.status_by_exit_code)
STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests", 36: "timeout", 24: "timeout",
          -24: "timeout", 152: "timeout", 255: "timeout", 34: "skipped", 37: "type check", None: "not checked"}


def scope_globs() -> list[str]:
    out = []
    for module, functions in SCOPE.items():
        if functions is None:
            out.append(f"{module}.*")
        else:
            out.extend(f"{module}.{f}*" for f in functions)
    return out


def in_scope(name: str) -> bool:
    module, _, func = name.rpartition("__mutmut_")[0].rpartition(".")
    if module not in SCOPE:
        return False
    functions = SCOPE[module]
    return functions is None or any(func.startswith(f) for f in functions)


def load_results() -> dict[str, dict[str, str]]:
    """module -> {mutant name: status}, for the mutants in scope."""
    out: dict[str, dict[str, str]] = {}
    for meta in sorted((ROOT / "mutants").glob("twin/**/*.py.meta")):
        try:
            data = json.loads(meta.read_text())
        except ValueError:  # a run stopped while writing it: that module's results are lost
            print(f"unreadable {meta}: skipped", file=sys.stderr)  # noqa: T201
            continue
        module = str(meta.relative_to(ROOT / "mutants")).removesuffix(".py.meta").replace("/", ".")
        for name, code in data.get("exit_code_by_key", {}).items():
            if in_scope(name):
                out.setdefault(module, {})[name] = STATUS.get(code, f"exit {code}")
    return out


def load_equivalents() -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]]]:
    """Equivalent mutants by name ([mutant."name"]) and by rule ([[rule]]: regexes on the changed lines)."""
    if not EQUIVALENT_FILE.exists():
        return {}, []
    data = tomllib.loads(EQUIVALENT_FILE.read_text())
    return data.get("mutant", {}), data.get("rule", [])


def diff_of(name: str) -> str:
    """The mutant's diff against the original function (mutmut's own, in-process: `mutmut show` is slower)."""
    os.chdir(ROOT)
    from mutmut.mutation.diff_apply import get_diff_for_mutant

    module = name.rpartition("__mutmut_")[0].rpartition(".")[0]
    return get_diff_for_mutant(name, path=module.replace(".", "/") + ".py").strip()


def changed_lines(diff: str) -> tuple[list[str], list[str]]:
    lines = diff.splitlines()
    removed = [x[1:].strip() for x in lines if x.startswith("-") and not x.startswith("---")]
    added = [x[1:].strip() for x in lines if x.startswith("+") and not x.startswith("+++")]
    return removed, added


def _one_substitution(removed: str, added: str, subs: list[list[str]]) -> bool:
    """Whether ``added`` is ``removed`` with one occurrence of one (pattern, replacement) applied."""
    for pattern, replacement in subs:
        for m in re.finditer(pattern, removed):
            if removed[: m.start()] + m.expand(replacement) + removed[m.end():] == added:
                return True
    return False


def _rule_pair(removed: str, added: str, rule: dict[str, Any]) -> bool:
    """A (removed, added) line pair that the rule explains: one substitution, or a change inside strings only."""
    if rule.get("strings_only"):
        def unquote(line: str) -> str:
            return re.sub(r'"[^"]*"', '""', line)

        return removed != added and unquote(removed) == unquote(added)
    return _one_substitution(removed, added, rule.get("subs", []))


def equivalence(name: str, diff: str, by_name: dict[str, dict[str, Any]], rules: list[dict[str, Any]]
                ) -> dict[str, Any] | None:
    """Why the mutant is equivalent (an entry of mutation_equivalent.toml), or None.

    A rule matches a mutant whose changed lines pair up (removed, added) so that every pair is one
    of the rule's substitutions (``subs``: regex, replacement) applied once to the removed line,
    optionally only in some modules and only where the removed line matches ``where``.
    """
    if name in by_name:
        return by_name[name]
    module = name.rpartition("__mutmut_")[0].rpartition(".")[0]
    removed, added = changed_lines(diff)
    if not removed or len(removed) != len(added):
        return None
    for rule in rules:
        if rule.get("modules") and module not in rule["modules"]:
            continue
        pairs = zip(removed, added, strict=True)
        if all(re.search(rule.get("where", ""), r) and _rule_pair(r, a, rule) for r, a in pairs):
            return rule
    return None


def report(out: Path, summary: Path | None = None) -> float:
    results = load_results()
    by_name, rules = load_equivalents()
    rows, details = [], []
    tot: Counter[str] = Counter()
    for module, res in sorted(results.items()):
        c = Counter(res.values())
        notes = {}
        for name, st in res.items():
            if st not in ("killed", "timeout", "not checked"):  # not checked: listed by count only
                d = diff_of(name)
                notes[name] = (d, equivalence(name, d, by_name, rules))
        eq = sum(1 for name, (d, note) in notes.items() if note is not None and res[name] in ("survived", "no tests"))
        n = len(res)
        checked = n - c["not checked"]
        detected = c["killed"] + c["timeout"]
        score = detected / (checked - eq) if checked > eq else float("nan")
        rows.append(f"| {module} | {n} | {c['killed']} | {c['survived']} | {c['timeout']} | {c['no tests']} "
                    f"| {c['not checked']} | {eq} | {100 * score:.1f} % | {100 * detected / max(checked, 1):.1f} % |")
        tot.update(c)
        tot["equivalent"] += eq
        tot["n"] += n
        for name, (d, note) in sorted(notes.items(), key=lambda kv: (kv[1][1] is not None, kv[0])):
            st = res[name]
            head = f"#### `{name}`: {st}" + (" (equivalent)" if note else "")
            body = [head, "", "```diff", d, "```"]
            if note:
                body += ["", f"Equivalent: {note['reason']}"]
            change = (note or {}).get("likely_to_change") or LIKELY_TO_CHANGE.get(module)
            if change:
                body += ["", f"Code likely to change: {change}"]
            details.append("\n".join(body))
    detected = tot["killed"] + tot["timeout"]
    checked = tot["n"] - tot["not checked"]
    score = detected / (checked - tot["equivalent"])
    rows.append(f"| **all** | {tot['n']} | {tot['killed']} | {tot['survived']} | {tot['timeout']} | "
                f"{tot['no tests']} | {tot['not checked']} | {tot['equivalent']} | **{100 * score:.1f} %** | "
                f"{100 * detected / checked:.1f} % |")
    text = "\n".join([
        "# Mutation report of the numerics",
        "",
        "Written by `bash scripts/mutation.sh` (mutmut, settings in `[tool.mutmut]` of pyproject.toml; scope and",
        "score in `scripts/mutation_report.py`; equivalent mutants with their reasons in",
        "`scripts/mutation_equivalent.toml`).  Score = (killed + timeout) / (checked - equivalent), checked =",
        "mutants - not checked (a run stopped before it reached them: `bash scripts/mutation.sh --survivors`",
        "goes on); the raw score counts the equivalent ones as survivors.  Not mutated by mutmut:",
        "module-level constants and decorated functions (properties, cached properties), e.g. the FE",
        "matrices M, K, G, M_theta, c_m;",
        "`tests/test_mutants.py` plants fixed mutants there (and at the places the suite once missed).",
        "The score before issue 17's tests: docs/mutation-before.md.",
        "",
        "| module | mutants | killed | survived | timeout | no tests | not checked | equivalent | score | raw |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
        "## Mutants not killed",
        "",
        *(d + "\n" for d in details),
    ])
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    if summary is not None:  # the scores without the diffs: what the documentation keeps
        head = text.split("\n## Mutants not killed")[0].replace("# Mutation report of the numerics", "# Mutation testing")
        summary.write_text(head.rstrip() + "\n\n" + SUMMARY_TAIL)
    return score


SUMMARY_TAIL = (
    "The full report, with every mutant not killed, its diff and why it is equivalent (about 4,400 lines), is an\n"
    "artifact of the run: `test-artifacts/mutation-report.md` (not committed; `bash scripts/mutation.sh\n"
    "--report-only` writes it again from `./mutants`).\n"
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scope", action="store_true", help="print the mutmut name globs in scope")
    ap.add_argument("--not-killed", action="store_true", help="print the names of the mutants not killed")
    ap.add_argument("--skip-equivalent", action="store_true", help="with --not-killed: leave out the equivalent ones")
    ap.add_argument("--out", type=Path, help="write the report here")
    ap.add_argument("--summary", type=Path, help="with --out: also the scores alone, here (docs/mutation.md)")
    a = ap.parse_args()
    if a.scope:
        print(" ".join(scope_globs()))  # noqa: T201
    elif a.not_killed:
        results = load_results()
        names = [n for res in results.values() for n, st in res.items() if st not in ("killed", "timeout")]
        if a.skip_equivalent:
            by_name, rules = load_equivalents()
            names = [n for n in names if equivalence(n, diff_of(n), by_name, rules) is None]
        # a module without results yet (never run, or its results lost): all of it
        names += [g for g in scope_globs() if g.split(".x")[0].removesuffix(".*") not in results]
        print(" ".join(sorted(names)))  # noqa: T201
    elif a.out:
        score = report(a.out, a.summary)
        print(f"score {100 * score:.1f} %", file=sys.stderr)  # noqa: T201
    else:
        ap.print_help()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
