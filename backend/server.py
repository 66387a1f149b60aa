"""``furnace-twin serve``: dashboard, REST API, websocket stream and viser 3D view in one process.

uvicorn serves the FastAPI app on ``host:port`` (loopback by default); the viser server runs
in the same process on its own port and thread.  The radiation model is loaded (or
ray-traced once and cached) in the background from the start (the app's lifespan): the server
answers at once, and runs posted meanwhile wait as ``queued``.
"""

from __future__ import annotations

import logging
from pathlib import Path

from pydantic import ValidationError

from backend.app import create_app
from backend.core.settings import DEFAULT_DATA_DIR, Settings, is_loopback
from backend.runs.loop_factory import DefaultLoopFactory
from twin.config import FurnaceConfig
from twin.limits import furnace_name

log = logging.getLogger(__name__)


def serve(
    cfg: FurnaceConfig,
    host: str = "127.0.0.1",
    port: int = 8000,
    viser_port: int = 8080,
    data_dir: str | Path | None = None,
    furnace: str | None = None,
    rerun_connect: str | None = None,
    rerun_web_port: int | None = None,
    opcua_endpoint: str | None = None,
) -> int:
    """Run the server until interrupted; returns the process exit status.

    ``furnace`` is the ``--config`` value that ``cfg`` came from (its label in ``GET /api/furnace``).
    ``rerun_connect`` (or ``FURNACE_TWIN_RERUN_CONNECT``): every run also streams live to that rerun viewer
    or gRPC proxy; ``rerun_web_port`` (default 9090, 0 = none): the rerun web viewer on loopback;
    ``opcua_endpoint`` (or ``FURNACE_TWIN_OPCUA_RESULTS_ENDPOINT``): the twin's results served read-only over OPC UA
    (:mod:`backend.streaming.opcua_results`).
    A non-loopback ``host`` is refused unless an API token is set
    (``FURNACE_TWIN_API_TOKEN``), so the furnace is never controllable from the network
    without one.
    """
    import uvicorn

    given: dict[str, object] = {"data_dir": Path(data_dir) if data_dir else DEFAULT_DATA_DIR, "host": host,
                                "port": port, "viser_port": viser_port}
    if rerun_connect:
        given["rerun_connect"] = rerun_connect
    if rerun_web_port is not None:
        given["rerun_web_port"] = rerun_web_port
    if opcua_endpoint:
        given["opcua_results_endpoint"] = opcua_endpoint
    try:
        settings = Settings(**given)  # type: ignore[arg-type]  # the rest from defaults / environment
    except ValidationError as exc:
        log.error("invalid server settings (FURNACE_TWIN_...): %s", "; ".join(
            f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()))
        return 2
    if not is_loopback(host) and not settings.api_token:
        log.error("refusing to listen on %s without an API token: set FURNACE_TWIN_API_TOKEN "
                  "(or keep the default 127.0.0.1)", host)
        return 2
    factory = DefaultLoopFactory(settings)
    app = create_app(settings, cfg, loop_factory=factory, viser=True, rerun=True,
                     furnace_name=furnace_name(cfg, furnace) if furnace else None)
    log.info("dashboard on http://%s:%d/ , data in %s", host, port, settings.data_dir.resolve())
    server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="info"))
    server.run()
    return 0
