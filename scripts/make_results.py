"""The documentation's results pages, generated from the stored campaign JSON in ``docs/data/``.

    python scripts/make_results.py              # docs/results/<name>.md for every docs/data/<name>.json
    python scripts/make_results.py --check      # exit 1 if a page differs from what its JSON gives
    python scripts/make_results.py --run small  # re-run the reduced campaign into docs/data/campaign-small.json
    python scripts/make_results.py --store default DIR "furnace-twin campaign --out DIR"
                                                # DIR/campaign.json -> docs/data/campaign-default.json
    python scripts/make_results.py --store banded DIR "furnace-twin --config banded campaign --estimator both --out DIR"
                                                # with the paper's estimator beside the default in the same JSON
    python scripts/make_results.py --store-paper default DIR "furnace-twin campaign --estimator paper --out DIR"
                                                # a paper's-estimator campaign into campaign-default.json

A data file holds the campaign's own ``campaign.json`` object (``furnace-twin campaign``, product.md) under
``"campaign"``, with how it was made: ``{"title", "command", "furnace", "t_E", "campaign"}``.  The page is that
provenance above the campaign's own report (``twin.experiments.campaign.campaign_report``: the worst over the
seeds beside the paper's bounds, the range over the seeds, the model against the truth), so a page can only
say what the stored run said.  ``tests/test_results_pages.py`` checks every page against its JSON.

The paper's estimator beside the default (``furnace-twin campaign --estimator both``: the paper's runs under
``"paper_estimator"`` in the same ``campaign.json``) is stored with the rest and its page ends with the comparison
(paper -> default).  A campaign stored without it takes one afterwards with ``--store-paper NAME DIR COMMAND``
(DIR a ``--estimator paper`` campaign on the same furnace, seeds, truth and t_E; checked), so the default's runs
are not run twice.  Pages that used to carry these tables (``docs/estimation.md``, ``docs/truth.md``) hold a
section between ``<!-- results:NAME:paper -->`` markers: once the JSON has the comparison, it becomes a link to
the generated page; until then the section is left as it is.

A campaign on the default furnace (``furnace-twin campaign --out DIR``, about 35 min on 2 cores) is stored the
same way (``--store default DIR COMMAND``).  The README's headline table is made here too, from
``docs/data/campaign-default.json``: the range over the seeds of each metric, fixed and oscillating, beside the
paper's bounds; it sits between the README's ``<!-- results:campaign-default -->`` markers, and
``tests/test_readme.py`` checks it against the JSON's seeds.  So is the README's coverage table (between
``<!-- results:coverage -->`` markers): the reported band's share of the true field per stored campaign
(``COVERAGE_FURNACES``) and specimen mode, the mean over the seeds beside each seed's (issue 25).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "docs" / "data"
PAGES = ROOT / "docs" / "results"

README = ROOT / "README.md"
MKDOCS = ROOT / "mkdocs.yml"

#: the reduced campaign of tests/experiments/test_campaign.py: small furnace, t_E = 30 s, 2 seeds, honest truth
SMALL = {"t_E": 30.0, "seeds": 2}

#: the README's headline rows: its words -> the campaign's metric (the true field's rows: what a user's specimen
#: got, which only a simulation can see; the others: what the twin showed)
README_ROWS = {
    "true mean error, transient": "true_mean_error_transient_max",
    "mean error (estimated), transient": "mean_error_transient_max",
    "true mean error, steady": "true_mean_error_steady_max",
    "mean error (estimated), steady": "mean_error_steady_max",
    "TC4 error, transient": "tc4_error_transient_max",
    "TC4 error, steady": "tc4_error_steady_max",
    "true inhomogeneity, steady": "true_inhomogeneity_steady",
    "inhomogeneity (estimated), steady": "inhomogeneity_steady",
}
README_BEGIN, README_END = "<!-- results:campaign-default -->", "<!-- /results:campaign-default -->"


#: the campaigns a campaign.json may carry beside its own runs (``furnace-twin campaign``'s ``--estimator both``,
#: ``--controller both``, ``--calibration learn``), each a campaign.json object of its own
NESTED = ("paper_estimator", "mpc", "second_run", "mpc_second_run")
PAPER_HEADING = "## The paper's estimator beside the default"  # campaign_report's section


def render(doc: dict[str, Any]) -> str:
    """The results page of one data file (markdown)."""
    from twin.experiments.campaign import campaign_report

    report = campaign_report(doc["campaign"], float(doc["t_E"]))
    body = report.split("\n", 1)[1]  # the page's title is the data's own
    def at(key: str) -> str:
        return f"; stored at commit {doc[key]}" if doc.get(key) else ""

    paper = (f"The paper's estimator: `{doc['paper_command']}`{at('paper_commit')}.\n" if doc.get("paper_command")
             else "")
    return (f"# {doc['title']}\n\n"
            f"Generated by `scripts/make_results.py` from `docs/data/{doc['name']}.json`; do not edit by hand.\n"
            f"The run: `{doc['command']}` (furnace `{doc['furnace']}`{at('commit')}).\n"
            + paper + body)


def head_commit() -> str | None:
    """The repository's commit now (what a campaign stored right after it ran was run on); None outside git."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip() or None
    except (OSError, subprocess.CalledProcessError):
        return None


def load(path: Path) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads(path.read_text())
    doc["name"] = path.stem
    return doc


#: documentation pages (in docs/) with ``<!-- results:NAME:paper -->`` sections (:func:`doc_sections`)
DOC_PAGES = ("estimation.md", "truth.md")


def pages() -> dict[Path, str]:
    """Every page as its JSON gives it."""
    return {PAGES / f"{p.stem}.md": render(load(p)) for p in sorted(DATA.glob("campaign-*.json"))}


def nav_with_pages(yml: str, docs: dict[str, dict[str, Any]]) -> str:
    """``mkdocs.yml`` with a Results entry for every stored campaign's page (after the last one there; the site
    build fails on a page left out of the nav)."""
    lines = yml.split("\n")
    for name, doc in docs.items():
        if f"results/{name}.md" in yml:
            continue
        last = max(i for i, line in enumerate(lines) if "results/campaign-" in line or "results/index.md" in line)
        indent = lines[last][: len(lines[last]) - len(lines[last].lstrip())]
        lines.insert(last + 1, f"{indent}- {doc['title'].replace('`', '')}: results/{name}.md")
        yml = "\n".join(lines)
    return yml


def doc_pages() -> dict[Path, str]:
    """The documentation pages with results sections, as the stored JSON makes them."""
    docs = {p.stem: load(p) for p in sorted(DATA.glob("campaign-*.json"))}
    out = {PAGES.parent / name: doc_sections((PAGES.parent / name).read_text(), docs) for name in DOC_PAGES
           if (PAGES.parent / name).is_file()}
    if MKDOCS.is_file():
        out[MKDOCS] = nav_with_pages(MKDOCS.read_text(), docs)
    return out


def run_small() -> None:
    """The reduced campaign, stored as docs/data/campaign-small.json."""
    from twin.config import small_config
    from twin.experiments.campaign import run_campaign

    with tempfile.TemporaryDirectory() as out:
        result = run_campaign(small_config(), Path(out), t_E=SMALL["t_E"], seeds=SMALL["seeds"], figures=False)
    for e in result["experiments"]:  # temporary folders: not worth storing
        for s in e["seeds"]:
            s.pop("out", None)
    doc = {"title": "Reduced campaign (small furnace)", "furnace": "small_config()", "t_E": SMALL["t_E"],
           "command": "python scripts/make_results.py --run small", "campaign": result}
    (DATA / "campaign-small.json").write_text(json.dumps(doc, indent=1) + "\n")


def seed_range(experiments: list[dict[str, Any]], key: str, oscillating: bool) -> tuple[float, float]:
    """Lowest and highest of a metric over the seeds of every experiment of one specimen mode (so over the TC4
    places too), in % of the setpoint."""
    values = [100 * float(s["metrics"][key]) for e in experiments if bool(e["oscillation"]) == oscillating
              for s in e["seeds"]]
    return min(values), max(values)


def readme_table(doc: dict[str, Any]) -> str:
    """The README's headline table from a stored campaign: each row's range over the seeds, fixed and
    oscillating, beside the paper's bound (in parentheses where the paper bounds the estimated quantity); ✗ where
    the worst seed is above it."""
    from twin.experiments.campaign import TRUE_BOUND_OF, bound

    lines = ["| metric | paper fixed | paper osc. | twin fixed | twin oscillating |", "|---|---|---|---|---|"]
    for words, key in README_ROWS.items():
        cells = []
        for mode in ("fixed", "oscillating"):
            limit = bound(key, mode)
            cells.append("-" if limit is None else
                         f"({100 * limit:.2f} %)" if key in TRUE_BOUND_OF else f"{100 * limit:.2f} %")
        for oscillating, mode in ((False, "fixed"), (True, "oscillating")):
            lo, hi = seed_range(doc["campaign"]["experiments"], key, oscillating)
            limit = bound(key, mode)
            cells.append(f"{lo:.2f} - {hi:.2f} %" + (" ✗" if limit is not None and hi > 100 * limit else ""))
        lines.append(f"| {words} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


#: the README's coverage table (issue 25): the stored campaigns it is made from, in its order
COVERAGE_FURNACES = ("default", "banded")
COVERAGE_BEGIN, COVERAGE_END = "<!-- results:coverage -->", "<!-- /results:coverage -->"


def coverage_readme_table() -> str:
    """The README's table of the reported band's truth: per stored campaign and specimen mode, the steady window's
    2-sigma coverage of the true field (mean over the seeds, each seed's) and the smallest transient, from the
    first experiment of the mode (the TC4 places of one mode share their loop, so their coverages are the same)."""
    from twin.experiments.campaign import COVERAGE_BAND, COVERAGE_TRANSIENT_MIN, seed_values

    lo, hi = COVERAGE_BAND
    lines = [f"| furnace, specimen | steady: mean over the seeds ({100 * lo:g}-{100 * hi:g} %) | each seed | "
             f"transient, smallest (>= {100 * COVERAGE_TRANSIENT_MIN:g} %) |", "|---|---|---|---|"]
    for name in COVERAGE_FURNACES:
        path = DATA / f"campaign-{name}.json"
        if not path.is_file():
            continue
        for oscillating, mode in ((False, "fixed"), (True, "oscillating")):
            exp = [e for e in load(path)["campaign"]["experiments"] if bool(e["oscillation"]) == oscillating]
            if not exp:
                continue
            steady = seed_values(exp[0], "coverage_2sigma_steady")
            transient = seed_values(exp[0], "coverage_2sigma_transient")
            if not steady or not transient:
                continue  # a campaign without a true field, or stored before the reported covariance
            lines.append(f"| `{name}`, {mode} | {100 * sum(steady) / len(steady):.1f} % | "
                         + ", ".join(f"{100 * v:.1f}" for v in steady) + f" | {100 * min(transient):.1f} % |")
    return "\n".join(lines)


def readme_with_table(readme: str) -> str:
    """The README with its headline table made again from ``docs/data/campaign-default.json`` (and its coverage
    table, when it has the markers, from the stored campaigns of ``COVERAGE_FURNACES``)."""
    head, rest = readme.split(README_BEGIN, 1)
    _, tail = rest.split(README_END, 1)
    table = readme_table(load(DATA / "campaign-default.json"))
    readme = f"{head}{README_BEGIN}\n{table}\n{README_END}{tail}"
    if COVERAGE_BEGIN in readme:
        head, rest = readme.split(COVERAGE_BEGIN, 1)
        _, tail = rest.split(COVERAGE_END, 1)
        readme = f"{head}{COVERAGE_BEGIN}\n{coverage_readme_table()}\n{COVERAGE_END}{tail}"
    return readme


def _stored(out: Path) -> tuple[dict[str, Any], float]:
    """A ``furnace-twin campaign`` folder's ``campaign.json`` without the run folders (they were on the machine
    that ran it), and its t_E (the campaign's own report says it: "seeds 0..4; t_E = 120 s."; the JSON does not)."""
    result: dict[str, Any] = json.loads((out / "campaign.json").read_text())
    for campaign in [result, *(result[k] for k in NESTED if k in result)]:
        for e in campaign["experiments"]:
            for s in e["seeds"]:
                s.pop("out", None)
    found = re.search(r"t_E = ([\d.]+) s", (out / "campaign.md").read_text())
    if found is None:
        raise SystemExit(f"{out / 'campaign.md'} does not say its t_E: not a furnace-twin campaign folder?")
    return result, float(found.group(1))


def store(name: str, out: Path, command: str) -> None:
    """``out/campaign.json`` (a ``furnace-twin campaign`` folder) as ``docs/data/campaign-<name>.json``."""
    result, t_E = _stored(out)
    doc = {"title": f"Campaign on the `{name}` furnace", "furnace": name, "t_E": t_E, "command": command,
           "commit": head_commit(), "campaign": result}
    (DATA / f"campaign-{name}.json").write_text(json.dumps(doc, indent=1) + "\n")


def store_paper(name: str, out: Path, command: str) -> None:
    """A ``--estimator paper`` campaign folder into ``docs/data/campaign-<name>.json`` as its ``paper_estimator``,
    as ``--estimator both`` would have put it; SystemExit if it did not run the same plants (furnace, seeds,
    truth, t_E, experiments) with the paper's estimator."""
    path = DATA / f"campaign-{name}.json"
    doc = json.loads(path.read_text())
    paper, t_E = _stored(out)
    base = doc["campaign"]
    problems = [f"{what}: {theirs!r}, the stored campaign's {ours!r}" for what, theirs, ours in (
        ("estimator", paper.get("estimator", {}).get("name"), "paper"),
        ("t_E", t_E, float(doc["t_E"])),
        ("seeds", paper["seeds"], base["seeds"]),
        ("truth", paper["truth"], base["truth"]),
        ("experiments", [e["name"] for e in paper["experiments"]], [e["name"] for e in base["experiments"]]),
    ) if theirs != ours]
    if problems:
        raise SystemExit(f"{out} is not the paper's estimator on {path.name}'s plants: " + "; ".join(problems))
    base["paper_estimator"] = paper
    doc["paper_command"], doc["paper_commit"] = command, head_commit()
    path.write_text(json.dumps(doc, indent=1) + "\n")


def doc_sections(text: str, docs: dict[str, dict[str, Any]]) -> str:
    """``text`` (a documentation page) with each ``<!-- results:NAME:paper -->`` section whose campaign has the
    paper's estimator beside it made a link to its generated page; other sections as they are."""
    def link(m: re.Match[str]) -> str:
        name = m.group(1)
        doc = docs.get(name)
        if doc is None or "paper_estimator" not in doc["campaign"]:
            return m.group(0)
        return (f"<!-- results:{name}:paper -->\n\n"
                f"The paper's estimator beside the default on the `{doc['furnace']}` furnace (its own runs, then "
                f"each metric's worst over the seeds as paper -> default) is [generated from the stored "
                f"campaign](results/{name}.md), with the commands that made it."
                f"\n\n<!-- /results:{name}:paper -->")

    return re.sub(r"<!-- results:([\w-]+):paper -->\n.*?<!-- /results:\1:paper -->", link, text, flags=re.S)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare the pages with their JSON, write nothing")
    ap.add_argument("--run", choices=["small"], help="re-run a campaign into docs/data first")
    ap.add_argument("--store", nargs=3, metavar=("NAME", "DIR", "COMMAND"),
                    help="store DIR/campaign.json as docs/data/campaign-NAME.json, made by COMMAND")
    ap.add_argument("--store-paper", nargs=3, metavar=("NAME", "DIR", "COMMAND"),
                    help="add DIR (a --estimator paper campaign, made by COMMAND) to docs/data/campaign-NAME.json")
    args = ap.parse_args(argv)
    if args.run == "small":
        run_small()
    if args.store:
        store(args.store[0], Path(args.store[1]), args.store[2])
    if args.store_paper:
        store_paper(args.store_paper[0], Path(args.store_paper[1]), args.store_paper[2])
    stale = []
    for path, text in {**pages(), **doc_pages()}.items():
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(path)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
    if (DATA / "campaign-default.json").is_file():
        text = readme_with_table(README.read_text())
        if not args.check:
            README.write_text(text)
        elif README.read_text() != text:
            stale.append(README)
    for path in stale:
        print(f"{path} differs from its JSON: python scripts/make_results.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
