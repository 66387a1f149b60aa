"""How the twin finds and rides through injected faults, measured: ``python scripts/fault_study.py``.

Each case is the default run (or the one given) with one fault injected at ``at``, repeated for several
noise seeds and with the fault-free run of the same seed beside it.  Per case and seed:

- ``detected_after_s``: from the onset to the first decision of the fault detector about the faulty
  TC or lamp group (``None``: not found within the run); ``kind``: what it said; ``failed_after_s``: for a
  lamp group, until it was taken as failed (a first decision may be a derate);
- ``false``: decisions about anything else (in the faulty run, and in the fault-free one);
- ``tc4_after``: max |TC4 - estimate at TC4| (K) from the onset to the end, and ``tc4_after_ok``: the
  same in the fault-free run; their ratio is the ride-through figure for TC faults (the TC4 reading
  itself is trusted here unless TC4 is the faulty one);
- ``mean_error_steady``, ``inhomogeneity_steady``: the run's metrics (K), faulty and fault-free.

Example (one short case; the default is the whole table)::

    python scripts/fault_study.py --seeds 3 --json out/faults.json
    python scripts/fault_study.py --seeds 3 --estimator paper --json out/faults_paper.json

The runs go on the study engine's cluster (``twin.studies.cluster``): a LocalCluster of one process worker per
core by default, ``--workers N`` (``0``: one after another in this process), ``--scheduler tcp://HOST:8786`` to
go wide; the table does not depend on where they ran.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from typing import Any

import numpy as np

from twin.config import FurnaceConfig, load_config
from twin.scenario import Scenario

log = logging.getLogger(__name__)

#: (name, fault) of the study: every kind on a TC the estimator uses, and the lamp groups that carry power in
#: the default run's steady state (T3h is off there: its failure changes nothing and nothing can see it)
CASES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("TC1 stuck", {"target": "TC1", "kind": "stuck"}),
    ("TC2 stuck", {"target": "TC2", "kind": "stuck"}),
    ("TC2 dropout", {"target": "TC2", "kind": "dropout"}),
    ("TC3 dropout", {"target": "TC3", "kind": "dropout"}),
    ("TC1 offset +10 K", {"target": "TC1", "kind": "offset", "value": 10.0}),
    ("TC3 offset -5 K", {"target": "TC3", "kind": "offset", "value": -5.0}),
    ("TC2 drift +0.5 K/s", {"target": "TC2", "kind": "drift", "value": 0.5}),
    ("T2v failed", {"target": "T2v", "kind": "failed"}),
    ("T2h failed", {"target": "T2h", "kind": "failed"}),
    ("T1h failed", {"target": "T1h", "kind": "failed"}),
    ("T4h failed", {"target": "T4h", "kind": "failed"}),
    ("T2v derate 0.5", {"target": "T2v", "kind": "derate", "value": 0.5}),
)
DETECTED = "fault detected: "


def _run(cfg: FurnaceConfig, radiation: Any, scenario: Scenario, truth_radiation: Any, at: float) -> dict[str, Any]:
    """One run to its end: its metrics, the detector's decisions and max |TC4 - estimate| from ``at`` on."""
    from twin.furnace.simulated import SimulatedFurnace
    from twin.runs.loop import ClosedLoop

    furnace = SimulatedFurnace.for_scenario(cfg, scenario, radiation, truth_radiation=truth_radiation)
    loop = ClosedLoop(cfg, scenario, radiation, furnace=furnace)
    try:
        for _ in loop.run():
            pass
        detections = [(d.t, d.target, d.kind, d.text) for d in loop.detector.detections]
        return {"tc4_after": _tc4_max(loop.timeseries(), at), "metrics": loop.metrics(), "detections": detections}
    finally:
        loop.close()


def _run_on_worker(digest: str, furnace: dict[str, Any], scenario_json: str, own_truth: bool, at: float
                   ) -> dict[str, Any]:
    """:func:`_run` on a Dask worker: the furnace's tables from the worker's cache, loaded once per process
    (``twin.experiments.campaign_runs.furnace_tables``: a worker never ray-traces)."""
    from twin.experiments.campaign_runs import furnace_tables

    cfg, radiation, own = furnace_tables(digest, furnace, own_truth)
    return _run(cfg, radiation, Scenario.model_validate_json(scenario_json), own, at)  # validated as study() does


def _tc4_max(ts: dict[str, Any], t_from: float) -> float:
    t = np.asarray(ts["t"])
    keep = t >= t_from
    err = np.abs(np.asarray(ts["tc"])[keep, 3] - np.asarray(ts["tc_hat"])[keep, 3])
    return float(np.nanmax(err)) if np.isfinite(err).any() else float("nan")


def _all_runs(cfg: FurnaceConfig, scenarios: list[Scenario], at: float, workers: int | None,
              scheduler: str | None) -> list[dict[str, Any]]:
    """Every run of the study, in order: on the study engine's cluster (a LocalCluster of ``workers`` processes,
    default one per core, or the Dask scheduler at ``scheduler``), or here one after another (``workers=0``)."""
    from twin.experiments.campaign_runs import ensure_tables

    own_truth = any(s.truth == "independent" for s in scenarios)
    if workers == 0 and scheduler is None:
        from twin.furnace.simulated.truth import truth_radiation
        from twin.radiation import radiation_model

        radiation = radiation_model(cfg)
        own = truth_radiation(cfg) if own_truth else None
        return [_run(cfg, radiation, s, own if s.truth == "independent" else None, at) for s in scenarios]
    from twin.studies.cluster import study_client

    if __name__ != "__main__":  # imported (scripts is no package of the workers): send this module's code by value
        import cloudpickle

        cloudpickle.register_pickle_by_value(sys.modules[__name__])
    with study_client(workers=workers, scheduler=scheduler) as (client, n):
        ensure_tables(cfg, own_truth)
        log.info("fault study: %d runs on %d Dask workers", len(scenarios), n)
        furnace = client.scatter(cfg.model_dump(mode="json"), broadcast=True, hash=False)
        futures = [client.submit(_run_on_worker, cfg.digest(), furnace, s.to_json(), s.truth == "independent", at,
                                 pure=False)
                   for s in scenarios]
        return list(client.gather(futures))


def study(cfg: FurnaceConfig, *, seeds: int = 3, at: float = 150.0, oscillation: bool = False,
          cases: tuple[tuple[str, dict[str, Any]], ...] = CASES, base: dict[str, Any] | None = None,
          workers: int | None = None, scheduler: str | None = None) -> dict[str, Any]:
    """The table of the module docstring, as JSON-ready data (against the scenario's truth: the simulated
    furnace's own by default, ``base={"truth": "shared"}`` for the model's plant).  The runs go on the study
    engine's cluster (:func:`_all_runs`)."""
    base = {**(base or {}), "oscillation": {"enabled": oscillation}}
    setpoint = Scenario.model_validate(base).reference.setpoint
    clean_scenarios = [Scenario.model_validate({**base, "seed": seed}) for seed in range(seeds)]
    faulty = [(name, fault, seed) for name, fault in cases for seed in range(seeds)]
    faulty_scenarios = [Scenario.model_validate({**base, "seed": seed, "faults": [{**fault, "at": at}]})
                        for _, fault, seed in faulty]
    t0 = time.perf_counter()
    done = _all_runs(cfg, clean_scenarios + faulty_scenarios, at, workers, scheduler)
    log.info("fault study: %d runs in %.0f s", len(done), time.perf_counter() - t0)
    clean = dict(enumerate(done[:seeds]))
    rows: list[dict[str, Any]] = []
    for (name, fault, seed), res in zip(faulty, done[seeds:], strict=True):
        ok = clean[seed]
        mine = [d for d in res["detections"] if d[1] == fault["target"] and d[0] >= at]
        false = [d for d in res["detections"] if d not in mine and d[2] != "readmitted"]
        m, mo = res["metrics"], ok["metrics"]
        row = {
            "case": name, "seed": seed, "at": at,
            "detected_after_s": None if not mine else round(mine[0][0] - at, 2),
            "kind": None if not mine else mine[0][2], "said": None if not mine else mine[0][3],
            "failed_after_s": next((round(d[0] - at, 2) for d in mine if d[2] == "failed"), None),
            "false": [f"t={d[0]:.1f} {d[1]} {d[2]}" for d in false],
            "false_fault_free": [f"t={d[0]:.1f} {d[1]} {d[2]}" for d in ok["detections"] if d[2] != "readmitted"],
            "tc4_after": res["tc4_after"], "tc4_after_ok": ok["tc4_after"],
            "mean_error_steady": _k(m, "mean_error_steady_max", setpoint),
            "mean_error_steady_ok": _k(mo, "mean_error_steady_max", setpoint),
            "inhomogeneity_steady": _k(m, "inhomogeneity_steady", setpoint),
            "inhomogeneity_steady_ok": _k(mo, "inhomogeneity_steady", setpoint),
            "true_mean_error_steady": _k(m, "true_mean_error_steady_max", setpoint),
            "true_mean_error_steady_ok": _k(mo, "true_mean_error_steady_max", setpoint),
        }
        rows.append(row)
        log.info("%s seed %d: %s", name, seed, {k: row[k] for k in ("detected_after_s", "kind", "false",
                                                                     "tc4_after", "tc4_after_ok")})
    scenario = Scenario.model_validate(base)
    return {"oscillation": oscillation, "at": at, "seeds": seeds, "truth": scenario.truth,
            "estimator": scenario.estimator.model_dump(), "rows": rows}


def _k(metrics: dict[str, Any], key: str, setpoint: float) -> float | None:
    v = metrics.get(key)
    return None if v is None else round(float(v) * setpoint, 2)


def _estimator(name: str) -> dict[str, Any]:
    """The scenario's ``estimator`` for ``--estimator``: the default's is the scenario's own."""
    from twin.scenario import PAPER_ESTIMATOR

    return {"estimator": PAPER_ESTIMATOR.model_dump()} if name == "paper" else {}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--at", type=float, default=150.0, help="fault onset (s)")
    p.add_argument("--oscillate", action="store_true")
    p.add_argument("--case", action="append", help="only these cases (names of CASES)")
    p.add_argument("--config", default=None)
    p.add_argument("--truth", choices=("independent", "shared"), default="independent",
                   help="the simulated furnace's own truth (default) or the model's plant")
    p.add_argument("--estimator", choices=("default", "paper"), default="default",
                   help="the twin's default estimator or the paper's (averaged model, no calibration)")
    p.add_argument("--json", default=None, help="write the table here")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="LocalCluster process workers (default: one per core; 0: one run after another here)")
    where.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, e.g. tcp://host:8786")
    args = p.parse_args(argv)
    if args.workers is not None and args.workers < 0:
        p.error(f"--workers must be >= 0, got {args.workers}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    for noisy in ("twin.estimation", "twin.control", "twin.runs.loop"):
        logging.getLogger(noisy).setLevel(logging.ERROR)
    cases = tuple(c for c in CASES if not args.case or c[0] in args.case)
    from twin.studies.cluster import ClusterError

    try:
        out = study(load_config(args.config), seeds=args.seeds, at=args.at, oscillation=args.oscillate, cases=cases,
                    base={"truth": args.truth, **_estimator(args.estimator)}, workers=args.workers,
                    scheduler=args.scheduler)
    except ClusterError as exc:
        sys.stderr.write(f"fault_study: {exc}\n")
        return 2
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    for r in out["rows"]:
        sys.stdout.write(f"{r['case']:22s} seed {r['seed']}: after {r['detected_after_s']} s ({r['kind']}; failed "
                         f"after {r['failed_after_s']}), "
                         f"TC4 {r['tc4_after']:.1f} vs {r['tc4_after_ok']:.1f} K, mean {r['mean_error_steady']} vs "
                         f"{r['mean_error_steady_ok']} K, inh {r['inhomogeneity_steady']} vs "
                         f"{r['inhomogeneity_steady_ok']} K, false {r['false']} / {r['false_fault_free']}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
