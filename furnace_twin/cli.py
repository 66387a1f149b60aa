"""The ``furnace-twin`` command line (product.md): serve, precompute, simulate, run, campaign, bench, study,
emulate, opcua-check.

Each sub-command lives in its own module and is imported only when used, so
``furnace-twin --help`` stays fast.  User errors (bad config, bad scenario file,
bad arguments) print one clear message and exit with status 2; they never end in
a traceback.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from typing import Any

log = logging.getLogger("twin")


def _rel_point(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (relative, e.g. 0.5,0.5), got {text!r}") from None
    if not (0 <= x <= 1 and 0 <= y <= 1):
        raise argparse.ArgumentTypeError("X,Y are relative to (L_s, W_s) and must lie in [0, 1]")
    return (x, y)


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return n


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="furnace-twin", description=__doc__.splitlines()[0])
    p.add_argument("--config", help="furnace TOML file, or a shipped furnace: default, banded (default: default)")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("serve", help="dashboard, REST API, websocket stream and viser 3D view")
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--port", type=int, default=8000)
    s.add_argument("--viser-port", type=int, default=8080)
    s.add_argument("--data-dir", default=None, help="runs database and recordings (default ./furnace-data)")
    s.add_argument("--rerun-connect", default=None, metavar="URL",
                   help="stream every run live to this rerun viewer or gRPC proxy, e.g. "
                        "rerun+http://127.0.0.1:9876/proxy (or FURNACE_TWIN_RERUN_CONNECT)")
    s.add_argument("--rerun-web-port", type=int, default=None,
                   help="port of the rerun web viewer on loopback (default 9090; 0 = none)")
    s.add_argument("--opcua-endpoint", default=None, metavar="URL",
                   help="serve the twin's results read-only over OPC UA here, e.g. "
                        "opc.tcp://127.0.0.1:4841/furnace-twin/results/ (off by default; security as "
                        "FURNACE_TWIN_OPCUA_SECURITY)")

    s = sub.add_parser("precompute", help="radiation exchange factors for all eta positions (cached): the twin's "
                       "model's and the simulated furnace's own")
    s.add_argument("--force", action="store_true", help="recompute even if cached")

    s = sub.add_parser("simulate", help="open-loop plant run: timeseries.npz and PNG figures")
    s.add_argument("--powers", default="0.6", help="group powers as fractions of u_max: one value or 6 comma-separated")
    s.add_argument("--schedule", default=None, help="JSON file [[t, [u1..u6]], ...] (zero-order hold)")
    s.add_argument("--duration", type=float, default=240.0, help="s")
    s.add_argument("--oscillate", action="store_true", help="eta = amplitude sin(2 pi t / period)")
    s.add_argument("--amplitude", type=float, default=None,
                   help="m (default: the furnace's, 3 L_h capped at its eta_max)")
    s.add_argument("--period", type=float, default=None, help="s (default 18)")
    s.add_argument("--tc4", type=_rel_point, default=(0.5, 0.5))
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--truth", choices=("independent", "shared"), default="independent",
                   help="the simulated furnace: its own [truth] (default) or the model's plant")
    s.add_argument("--out", default="out/simulate")

    s = sub.add_parser("run", help="one headless closed-loop run")
    s.add_argument("--scenario", default=None, help="scenario JSON file (product.md)")
    s.add_argument("--oscillate", action="store_true")
    s.add_argument("--tc4", type=_rel_point, default=None)
    s.add_argument("--out", default="out/run")
    s.add_argument("--json", action="store_true", help="print the metrics as JSON")
    s.add_argument("--no-figures", dest="figures", action="store_false",
                   help="only the data (metrics.json, timeseries.npz, recording.rrd): no signals.png, field.png")

    s = sub.add_parser("campaign", help="the paper's six experiments, several seeds each, and a comparison table")
    s.add_argument("--out", default="out/campaign")
    s.add_argument("--json", action="store_true")
    s.add_argument("--t-e", type=float, default=None, help="shorten the transition time (s) for a quick look")
    s.add_argument("--seeds", type=int, default=5, help="seeds per experiment (0 .. N-1; TC noise and biases)")
    s.add_argument("--truth", choices=("independent", "shared"), default="independent",
                   help="the simulated furnace: its own [truth] (default) or the model's plant, to compare")
    s.add_argument("--estimator", choices=("default", "paper", "both"), default="default",
                   help="the twin's default estimator, the paper's (averaged model, no calibration), or both "
                        "side by side (the paper's runs in OUT/paper_estimator)")
    s.add_argument("--controller", choices=("default", "lqg", "mpc", "both"), default="default",
                   help="the feedback: the furnace's [control] feedback, the paper's LQG, the MPC, or both side by "
                        "side (the MPC's runs in OUT/mpc)")
    s.add_argument("--calibration", choices=("none", "learn"), default="none",
                   help="learn: run every recipe a second time, planned with what its first run learnt (the "
                        "calibration memory's rule; in OUT/second_run)")
    s.add_argument("--experiments", nargs="+", default=None, metavar="NAME",
                   help="only these experiments (e.g. fixed_tc4_0.5); default all six")
    where = s.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, default=None,
                       help="LocalCluster process workers for the runs (default: one per core)")
    where.add_argument("--scheduler", default=None,
                       help="address of a running Dask scheduler, e.g. tcp://host:8786 (the runs' files come back)")

    s = sub.add_parser("bench", help="performance figures")
    s.add_argument("--json", action="store_true")
    s.add_argument("--hil", action="store_true",
                   help="instead: hardware-in-the-loop timing against furnace-twin emulate (real time)")
    s.add_argument("--duration", type=float, default=300.0, help="--hil: seconds of real time (default 300)")

    s = sub.add_parser("emulate", help="the simulated furnace served in real time over OPC UA (hardware in the loop)")
    from twin.furnace.emulator.command import add_arguments as emulate_arguments

    emulate_arguments(s)

    s = sub.add_parser("opcua-check", help="browse a furnace's OPC UA server: each node the twin needs, its NodeId, "
                                           "type and access (writes nothing)")
    from twin.furnace.opcua.check import add_arguments as check_arguments

    check_arguments(s)

    s = sub.add_parser("place-tcs", help="rank thermocouple positions by the information they give about the field "
                                         "(paper, Remark 3)")
    from twin.experiments.place_tcs import add_arguments as place_arguments

    place_arguments(s)

    s = sub.add_parser("study", help="a design study (grid and/or Monte Carlo of runs) on Dask distributed")
    s.add_argument("file", help="study TOML file (product.md: furnace, [base], [grid], [monte_carlo])")
    s.add_argument("--out", default=None, help="study folder (default out/studies/<file name>); re-run to resume")
    where = s.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, default=None,
                       help="LocalCluster process workers (default: one per core)")
    where.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, e.g. tcp://host:8786")
    s.add_argument("--json", action="store_true", help="print the study result as JSON")
    s.add_argument("--keep-series", action="store_true", help="keep each case's timeseries.npz")
    for sp in sub.choices.values():  # --config also after the command (furnace-twin campaign --config banded)
        sp.add_argument("--config", default=argparse.SUPPRESS, help="as before the command")
    return p


def _recording_sink(cfg: Any) -> Any:
    """Factory of the rerun recording (``recording.rrd``) of a headless run; twin never imports rerun."""

    def make(out: Any, loop: Any) -> Any:
        from backend.storage.recording import RecordingSink

        out.mkdir(parents=True, exist_ok=True)  # the sinks are made before the run's folder writes its first file
        return RecordingSink(
            cfg, out.name or "run", out / "recording.rrd", tc_positions=[tuple(p) for p in loop.tc_positions]
        )

    return make


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    if not args.verbose:  # asyncua reports every node it creates and every session at INFO
        logging.getLogger("asyncua").setLevel(logging.WARNING)
    from twin.config import CONFIG_ENV_VAR, ConfigError, load_config

    try:
        cfg = load_config(args.config)
        if args.command == "serve":
            from backend.server import serve

            return serve(cfg, host=args.host, port=args.port, viser_port=args.viser_port, data_dir=args.data_dir,
                         furnace=args.config or os.environ.get(CONFIG_ENV_VAR), rerun_connect=args.rerun_connect,
                         rerun_web_port=args.rerun_web_port, opcua_endpoint=args.opcua_endpoint)
        if args.command == "precompute":
            from twin.furnace.simulated.truth import precompute_truth
            from twin.radiation.cache import precompute_command

            status = precompute_command(cfg, force=args.force)
            precompute_truth(cfg, force=args.force)  # the simulated furnace's own table
            return status
        if args.command == "simulate":
            from twin.experiments.simulate import simulate_command

            return simulate_command(cfg, args)
        if args.command == "run":
            from twin.experiments.run import run_command

            return run_command(cfg, args, sink_factories=[_recording_sink(cfg)])
        if args.command == "campaign":
            from twin.experiments.campaign import campaign_command

            return campaign_command(cfg, args, sink_factories=[_recording_sink(cfg)])
        if args.command == "bench":
            from benchmarks.bench import bench_command

            return bench_command(cfg, args)
        if args.command == "emulate":
            from twin.furnace.emulator.command import emulate_command

            return emulate_command(cfg, args)
        if args.command == "opcua-check":
            from twin.furnace.opcua.check import check_command

            return check_command(cfg, args)
        if args.command == "place-tcs":
            from twin.experiments.place_tcs import place_tcs_command

            return place_tcs_command(cfg, args)
        if args.command == "study":
            from twin.studies.command import study_command

            return study_command(cfg, args)
    except ConfigError as exc:
        print(f"furnace-twin: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    except KeyboardInterrupt:
        return 130
    raise AssertionError(args.command)


if __name__ == "__main__":
    raise SystemExit(main())
