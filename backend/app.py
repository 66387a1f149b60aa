"""The FastAPI app factory: REST API, websocket stream, dashboard page, optional viser view.

>>> import tempfile
>>> from backend.settings import Settings
>>> from twin.config import small_config
>>> app = create_app(Settings(data_dir=tempfile.mkdtemp()), small_config())
>>> sorted(set(app.openapi()["paths"]) & {"/api/runs", "/api/health"})
['/api/health', '/api/runs']
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, HTTPException, Request, status
from fastapi.responses import FileResponse, JSONResponse

from backend.recovery import recover_interrupted
from backend.repository import RunRepository
from backend.routes import files, health, runs, stream
from backend.run_manager import LimitExceeded, PlantBusy, RunManager, RunNotActive, RunNotFound, TooManyRuns
from backend.run_worker import ChangeRejected, LoopFactory
from backend.settings import Settings
from twin.config import FurnaceConfig, load_config

log = logging.getLogger(__name__)



def assets_dir() -> Path:
    """The dashboard's files: the installed ``frontend_assets`` package (package data), or, in an
    editable install made before that package existed, the repository's ``frontend_assets`` folder."""
    try:
        from importlib.resources import files

        path = Path(str(files("frontend_assets")))
    except ModuleNotFoundError:
        path = Path(__file__).resolve().parent.parent / "frontend_assets"
    if not (path / "index.html").is_file():
        log.error("the dashboard's files are missing from %s", path)
    return path


ASSETS_DIR = assets_dir()
ASSET_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}


def plotly_bundle() -> Path:
    """The plotly.js bundle that the installed ``plotly`` Python package ships (no CDN)."""
    import plotly

    return Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"


def _error(code: int):  # noqa: ANN202 - small handler factory
    async def handler(_: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc) or type(exc).__name__}, status_code=code)

    return handler


def create_app(
    settings: Settings | None = None,
    cfg: FurnaceConfig | None = None,
    *,
    loop_factory: LoopFactory | None = None,
    viser: bool = False,
) -> FastAPI:
    """Build the app; the lifespan opens the database, marks crashed runs interrupted, and
    (with ``viser=True``) starts the 3D view on ``settings.viser_port``."""
    settings = settings or Settings()  # type: ignore[call-arg]  # defaults and environment
    cfg = cfg or load_config()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.runs_dir.mkdir(parents=True, exist_ok=True)
        repo = RunRepository(settings.db_path)
        recover_interrupted(repo, settings.runs_dir)
        manager = RunManager(settings, cfg, repo, loop_factory)
        app.state.settings, app.state.repo, app.state.manager = settings, repo, manager
        app.state.viser_url = None
        scene = None
        if viser and settings.viser_port:
            import asyncio

            from backend.viser_view import FurnaceView

            manager.event_loop = asyncio.get_running_loop()
            # always loopback: the 3D view has no token check, so it must not be reachable from the network
            scene = FurnaceView(cfg, manager, host="127.0.0.1", port=settings.viser_port)
            scene.start()
            app.state.viser_url = scene.url
        app.state.viser = scene
        try:
            yield
        finally:
            await manager.shutdown()
            if scene is not None:
                scene.stop()
            repo.close()

    app = FastAPI(
        title="furnace-twin",
        version="0.1.0",
        description="Live digital twin of the oscillating infrared annealing furnace "
        "(Jadachowski, Steinboeck, Kugi, CEP 78, 2018): runs, live stream, recordings.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.include_router(health.router)
    app.include_router(runs.router)
    app.include_router(files.router)
    app.include_router(stream.router)
    app.add_exception_handler(RunNotFound, _error(status.HTTP_404_NOT_FOUND))
    app.add_exception_handler(RunNotActive, _error(status.HTTP_409_CONFLICT))
    app.add_exception_handler(PlantBusy, _error(status.HTTP_409_CONFLICT))
    app.add_exception_handler(TooManyRuns, _error(status.HTTP_429_TOO_MANY_REQUESTS))
    app.add_exception_handler(LimitExceeded, _error(status.HTTP_422_UNPROCESSABLE_CONTENT))
    app.add_exception_handler(ChangeRejected, _error(status.HTTP_422_UNPROCESSABLE_CONTENT))

    @app.get("/", include_in_schema=False)
    def dashboard() -> FileResponse:
        return FileResponse(ASSETS_DIR / "index.html", media_type="text/html")

    @app.get("/assets/{name}", include_in_schema=False)
    def asset(name: str) -> FileResponse:
        if name == "plotly.min.js":
            return FileResponse(plotly_bundle(), media_type="text/javascript")
        path = ASSETS_DIR / name
        if "/" in name or name.startswith(".") or path.suffix not in ASSET_TYPES or not path.is_file():
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"no asset {name!r}")
        return FileResponse(path, media_type=ASSET_TYPES[path.suffix])

    return app
