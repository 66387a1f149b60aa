"""Open the furnace a scenario names (``plant``): the simulated one in process, or a furnace over OPC UA.

An OPC UA furnace is opened only at an endpoint the settings allow (``FURNACE_TWIN_OPCUA_ENDPOINTS``,
loopback by default); :func:`probe_furnace` checks an endpoint without touching the furnace (connect,
find every node, disconnect), so a server can refuse a run before it starts.

Example
-------
>>> from twin.furnace.opcua.options import OpcUaOptions
>>> check_endpoint("opc.tcp://127.0.0.1:4840/furnace-twin/", OpcUaOptions())    # loopback: allowed
>>> try:
...     check_endpoint("opc.tcp://10.1.2.3:4840/", OpcUaOptions())
... except EndpointNotAllowed as exc:
...     print(exc)  # doctest: +ELLIPSIS
opc.tcp://10.1.2.3:4840/ is not among the endpoints this server may connect to (FURNACE_TWIN_OPCUA_ENDPOINTS = ...)
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.endpoints import endpoint_allowed
from twin.furnace.interface import Furnace
from twin.furnace.opcua.options import OpcUaOptions, certificate_dir
from twin.scenario import Scenario

DEFAULT_DATA_DIR = Path("furnace-data")  # where certificates live when no data directory is given


class EndpointNotAllowed(ValueError):
    """The endpoint is not on this server's allow-list."""


def check_endpoint(endpoint: str, options: OpcUaOptions) -> None:
    """Raise :class:`EndpointNotAllowed` unless ``options.endpoints`` allows ``endpoint``."""
    if not endpoint_allowed(endpoint, options.allow_list()):
        raise EndpointNotAllowed(f"{endpoint} is not among the endpoints this server may connect to "
                                 f"(FURNACE_TWIN_OPCUA_ENDPOINTS = {options.endpoints})")


def open_furnace(cfg: FurnaceConfig, scenario: Scenario, radiation: Any, *, truth_radiation: Any = None,
                 opcua: OpcUaOptions | None = None, data_dir: str | Path = DEFAULT_DATA_DIR) -> Furnace:
    """The scenario's furnace; an OPC UA one connected, with the scenario's TC4 and drive settings commanded.

    A simulated furnace has the scenario's truth (``truth_radiation``: its own table, read from the cache
    if not given and needed); a furnace over OPC UA has none, whatever the scenario's ``truth`` says.

    Raises :class:`EndpointNotAllowed`, or ``FurnaceUnavailable`` (with a message) if it cannot be used."""
    plant = scenario.plant
    if plant.kind == "simulated":
        from twin.furnace.simulated import SimulatedFurnace

        return SimulatedFurnace.for_scenario(cfg, scenario, radiation, truth_radiation=truth_radiation)
    from twin.furnace.opcua.furnace import OpcUaFurnace

    options = opcua or OpcUaOptions()
    check_endpoint(plant.endpoint, options)
    return OpcUaFurnace(cfg, plant.endpoint, options=options, cert_dir=certificate_dir(data_dir), tc4=scenario.tc4,
                        oscillation=scenario.oscillation)


def probe_furnace(cfg: FurnaceConfig, scenario: Scenario, *, opcua: OpcUaOptions | None = None,
                  data_dir: str | Path = DEFAULT_DATA_DIR) -> None:
    """Check that the scenario's furnace can be used, writing nothing to it (call it from a worker thread:
    it runs its own event loop).  Raises like :func:`open_furnace`."""
    if scenario.plant.kind == "simulated":
        return
    from twin.furnace.opcua.furnace import CHANNELS
    from twin.furnace.opcua.link import FurnaceLink, LinkSettings
    from twin.furnace.opcua.nodes import load_mapping

    options = opcua or OpcUaOptions()
    check_endpoint(scenario.plant.endpoint, options)
    node_map = load_mapping(options.mapping, [g.name for g in cfg.lamps.groups])
    link = FurnaceLink(LinkSettings(scenario.plant.endpoint, options, certificate_dir(data_dir), node_map, CHANNELS),
                       lambda *_: None)

    async def probe() -> None:
        try:
            await link.open()
        finally:
            await link.close()

    asyncio.run(probe())
