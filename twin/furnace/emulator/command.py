"""``furnace-twin emulate``: the simulated furnace served in real time over OPC UA (hardware in the loop).

The furnace is ``SimulatedFurnace.for_scenario`` of the furnace config and the furnace-side fields of an
optional scenario file (its truth, mismatch, TC4, TC noise, seed, the initial drive settings, and whatever else the
simulated furnace takes from a scenario).  Without ``--security sign-encrypt`` the server listens only on
a loopback address unless ``--allow-insecure`` says otherwise.  Ctrl-C (or SIGTERM) stops it;
``--stats FILE`` then writes the timing figures (:mod:`twin.furnace.emulator.timing`) as JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.endpoints import is_loopback, parse_endpoint

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/furnace-twin/"
PASSWORD_ENV = "FURNACE_TWIN_OPCUA_PASSWORD"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--endpoint", default=DEFAULT_ENDPOINT, help=f"where to listen (default {DEFAULT_ENDPOINT})")
    p.add_argument("--scenario", default=None, help="scenario JSON: the simulated furnace's mismatch, TC4, noise, seed")
    p.add_argument("--security", choices=("none", "sign-encrypt"), default="none",
                   help="sign-encrypt: Basic256Sha256 Sign & Encrypt only; certificates in <data-dir>/opcua")
    p.add_argument("--user", default=None, help=f"require this user name; its password comes from ${PASSWORD_ENV}")
    p.add_argument("--data-dir", default="furnace-data", help="certificates in <data-dir>/opcua (created on first use)")
    p.add_argument("--mapping", default=None, help="serve the address space of an OPC UA mapping file")
    p.add_argument("--allow-insecure", action="store_true",
                   help="allow --security none on an address other than loopback (anyone on the network "
                        "could then drive the lamps)")
    p.add_argument("--stats", default=None, help="write the timing figures (JSON) here when stopped")
    p.add_argument("--lock-step", action="store_true",
                   help="no wall clock: the furnace advances one sample per watchdog value a client writes, with the "
                        "setpoints of that write (the twin then runs exactly as in process: for testing the "
                        "transport; the node LockStep says so)")
    p.add_argument("--load-on-first-client", action="store_true",
                   help="keep the specimen at its initial temperature until a client first enables the lamps "
                        "(a cold specimen loaded when the twin starts); by default it sits in the furnace from the "
                        "start and warms up to its surroundings")


class EmulateError(ValueError):
    """Bad arguments; the message says what to change."""


def check_arguments(args: Any) -> tuple[str, dict[str, str]]:
    """The endpoint (validated) and the users; :class:`EmulateError` for an unsafe or invalid combination."""
    try:
        ep = parse_endpoint(args.endpoint)
    except ValueError as exc:
        raise EmulateError(str(exc)) from None
    if args.security == "none" and not is_loopback(ep.host) and not args.allow_insecure:
        raise EmulateError(f"serving without security on {ep.host} (not a loopback address) lets anyone on that "
                           "network drive the lamps: use --security sign-encrypt, or --allow-insecure if you mean it")
    users: dict[str, str] = {}
    if args.user:
        password = os.environ.get(PASSWORD_ENV)
        if not password:
            raise EmulateError(f"--user {args.user} needs its password in ${PASSWORD_ENV}")
        users[args.user] = password
    return ep.url, users


def _install_stop(stop: asyncio.Event) -> None:
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)


def emulate_command(cfg: FurnaceConfig, args: Any) -> int:
    from twin.furnace.emulator.server import FurnaceEmulator
    from twin.furnace.opcua.nodes import MappingError, load_mapping
    from twin.furnace.opcua.options import certificate_dir
    from twin.furnace.simulated import SimulatedFurnace
    from twin.limits import scenario_limits
    from twin.radiation import radiation_model
    from twin.user_files import ScenarioError, load_scenario

    try:
        endpoint, users = check_arguments(args)
        scenario = load_scenario(args.scenario, scenario_limits(cfg))
        node_map = load_mapping(args.mapping, [g.name for g in cfg.lamps.groups])
    except (EmulateError, ScenarioError, MappingError) as exc:
        print(f"furnace-twin emulate: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    furnace = SimulatedFurnace.for_scenario(cfg, scenario, radiation_model(cfg))
    emulator = FurnaceEmulator(furnace, endpoint, node_map, eta_max=cfg.oscillation.eta_max,
                               T0=cfg.specimen.initial_temperature, security=args.security,
                               cert_dir=certificate_dir(args.data_dir), users=users,
                               load_on_first_client=args.load_on_first_client,
                               clock="lock-step" if getattr(args, "lock_step", False) else "realtime")

    async def main() -> None:
        stop = asyncio.Event()
        _install_stop(stop)
        await emulator.serve(stop)

    try:
        asyncio.run(main())
    except OSError as exc:
        print(f"furnace-twin emulate: cannot serve {endpoint}: {exc.strerror or exc}", file=sys.stderr)  # noqa: T201
        return 2
    finally:
        if args.stats:
            summary = {**emulator.timing.summary(), "interlock_trips": emulator.interlock.trips,
                       "late_ticks": emulator.overruns, "t_end": emulator.t}
            Path(args.stats).write_text(json.dumps(summary, indent=2))
    return 0
