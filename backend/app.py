"""The FastAPI app factory: REST API, websocket stream, dashboard page, optional viser view.

One router per resource (``backend/api/routes``): health, furnace, runs, run files, run stream, design
studies and the dashboard's page and files.  Everything they need comes from typed dependencies
(``backend/api/deps.py``); the run manager is the only way to the runs.

>>> import tempfile
>>> from backend.core.settings import Settings
>>> from twin.config import small_config
>>> app = create_app(Settings(data_dir=tempfile.mkdtemp()), small_config())
>>> sorted(set(app.openapi()["paths"]) & {"/api/runs", "/api/health"})
['/api/health', '/api/runs']
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request, status
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from backend.api.conformance import document_body_errors, http_error
from backend.api.links import add_links
from backend.api.routes import (
    dashboard,
    docs,
    exports,
    files,
    furnace,
    glossary,
    health,
    placement,
    rerun_page,
    runs,
    stream,
    studies,
)
from backend.api.schema_limits import apply_limits
from backend.core.errors import validation_error
from backend.core.security import SecurityMiddleware
from backend.core.settings import Settings
from backend.runs.factory import LoopFactory
from backend.runs.manager import (
    InsufficientStorage,
    LimitExceeded,
    PlantBusy,
    RequestConflict,
    RunIsActive,
    RunManager,
    RunNotActive,
    RunNotFound,
    TooManyRuns,
)
from backend.storage.recovery import recover_interrupted
from backend.storage.repository import RunRepository
from backend.studies.manager import StudyConflict, StudyManager, StudyNotFound, StudyRejected, StudyRunner
from backend.studies.placement import PlacementService, Rank
from twin.config import SHIPPED_FURNACES, FurnaceConfig, load_config
from twin.limits import scenario_limits
from twin.runs.changes import ChangeCancelled, ChangeRejected

log = logging.getLogger(__name__)

ERRORS: dict[type[Exception], int] = {
    RunNotFound: status.HTTP_404_NOT_FOUND,
    RunNotActive: status.HTTP_409_CONFLICT,
    PlantBusy: status.HTTP_409_CONFLICT,
    RunIsActive: status.HTTP_409_CONFLICT,
    RequestConflict: status.HTTP_409_CONFLICT,
    TooManyRuns: status.HTTP_429_TOO_MANY_REQUESTS,
    LimitExceeded: status.HTTP_422_UNPROCESSABLE_CONTENT,
    ChangeRejected: status.HTTP_422_UNPROCESSABLE_CONTENT,
    ChangeCancelled: status.HTTP_409_CONFLICT,
    InsufficientStorage: status.HTTP_507_INSUFFICIENT_STORAGE,
    StudyNotFound: status.HTTP_404_NOT_FOUND,
    StudyConflict: status.HTTP_409_CONFLICT,
    StudyRejected: status.HTTP_422_UNPROCESSABLE_CONTENT,
}


async def _error(request: Request, exc: Exception) -> JSONResponse:
    code = next(c for t, c in ERRORS.items() if isinstance(exc, t))
    return JSONResponse({"detail": str(exc) or type(exc).__name__}, status_code=code)


def create_app(
    settings: Settings | None = None,
    cfg: FurnaceConfig | None = None,
    *,
    loop_factory: LoopFactory | None = None,
    viser: bool = False,
    rerun: bool = False,
    furnace_name: str | None = None,
    study_runner: StudyRunner | None = None,
    placement_rank: Rank | None = None,
) -> FastAPI:
    """Build the app; the lifespan opens the database, marks crashed runs interrupted, starts the radiation
    models' warm-up, (with ``viser=True``) the 3D view on ``settings.viser_port`` and (with ``rerun=True``)
    the rerun web viewer on ``settings.rerun_web_port``.  ``furnace_name`` labels the furnace (``--config``);
    by default a shipped furnace's name or ``custom``.  ``study_runner`` replaces
    ``twin.studies.engine.run_study`` (tests of the studies API's plumbing), ``placement_rank``
    ``twin.experiments.place_tcs.rank_positions`` (``/api/placement``'s)."""
    settings = settings or Settings()  # type: ignore[call-arg]  # defaults and environment
    cfg = cfg or load_config()
    limits = scenario_limits(cfg, furnace_name)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.runs_dir.mkdir(parents=True, exist_ok=True)
        repo = RunRepository(settings.db_path)
        recover_interrupted(repo, settings.runs_dir)
        manager = RunManager(settings, cfg, repo, loop_factory, limits=limits,
                             event_loop=asyncio.get_running_loop())
        await asyncio.to_thread(manager.disk.apply_retention, repo, settings.runs_dir)
        manager.loop_factory.start_warm_up(cfg)  # the radiation model loads in the background; the server answers
        app.state.manager = manager
        app.state.studies = StudyManager(settings, cfg, study_runner, furnace_name=limits.furnace)
        # TC placement ranks on the twin's own radiation model (a stand-in loop factory may have none)
        app.state.placement = PlacementService(cfg, getattr(manager.loop_factory, "radiation", None), placement_rank)
        app.state.viser_url = None
        scene = None
        if viser and settings.viser_port:
            from backend.viser import FurnaceView

            # always loopback; its gate checks Host and Origin, and with a token only windows that entered it act
            scene = FurnaceView(manager, host="127.0.0.1", port=settings.viser_port, token=settings.api_token,
                                allowed_hosts=tuple(settings.allowed_hosts),
                                allowed_origins=tuple(settings.allowed_origins))
            scene.start()
            app.state.viser_url = scene.url
        app.state.viser = scene
        app.state.rerun_url = None
        viewer = None
        if rerun and settings.rerun_web_port:
            from backend.streaming.rerun_viewer import RerunWebViewer

            viewer = RerunWebViewer(settings.rerun_web_port, settings.rerun_grpc_port,
                                    server_memory_limit=settings.rerun_server_memory_limit,
                                    memory_limit=settings.rerun_memory_limit, log_dir=settings.data_dir)
            if await asyncio.to_thread(viewer.start):
                app.state.rerun_url = viewer.url
                if manager.live_url is None:
                    manager.live_url = viewer.proxy_url
            else:
                viewer = None
        app.state.rerun_viewer = viewer
        results = None
        if settings.opcua_results_endpoint:  # the twin's own results for the plant's SCADA (read-only)
            from backend.streaming.opcua_results import ResultsServer
            from twin.furnace.opcua.options import certificate_dir

            results = ResultsServer(manager, settings.opcua_results_endpoint, settings.opcua,
                                    certificate_dir(settings.data_dir))
            await asyncio.to_thread(results.start)
        app.state.opcua_results = results
        try:
            yield
        finally:
            if results is not None:
                await asyncio.to_thread(results.stop)
            await manager.shutdown()
            await asyncio.to_thread(app.state.studies.shutdown)
            if scene is not None:
                scene.stop()
            if viewer is not None:
                viewer.stop()
            repo.close()

    app = FastAPI(
        title="furnace-twin",
        version="0.1.0",
        description="Live digital twin of the oscillating infrared annealing furnace "
        "(Jadachowski, Steinboeck, Kugi, CEP 78, 2018): runs, live stream, recordings.",
        lifespan=lifespan,
        docs_url=None,  # backend/api/routes/docs.py: the same pages with their scripts from an installed package
        redoc_url=None,
    )
    app.state.settings = settings
    for module in (health, furnace, glossary, runs, files, exports, stream, studies, placement, rerun_page, dashboard,
                   docs):
        app.include_router(module.router)
    for exc_type in ERRORS:
        app.add_exception_handler(exc_type, _error)
    app.add_exception_handler(RequestValidationError, validation_error)  # plain words, short echoes
    app.add_exception_handler(StarletteHTTPException, http_error)  # a 405's Allow names every method of its path
    app.add_middleware(SecurityMiddleware, settings=settings)  # Host, Origin, content type, body size, token
    openapi = app.openapi

    def openapi_with_links() -> dict:
        """FastAPI's schema with links from each POST to the resource it made, and this server's bounds."""
        if app.openapi_schema is None:
            served = limits.capped(settings.max_duration_s, settings.max_speed)
            spec = document_body_errors(add_links(openapi()))
            app.openapi_schema = apply_limits(spec, served, tuple(SHIPPED_FURNACES))
        return app.openapi_schema

    app.openapi = openapi_with_links  # type: ignore[method-assign]
    return app
