"""The dashboard page (``/``) and its files (``/assets/...``), with plotly.js from the installed
``plotly`` package (no CDN).  Not part of the OpenAPI schema."""

from __future__ import annotations

import logging
from pathlib import Path

from fastapi import APIRouter, HTTPException, status
from fastapi.responses import FileResponse

log = logging.getLogger(__name__)
router = APIRouter(include_in_schema=False)


def assets_dir() -> Path:
    """The dashboard's files: the installed ``frontend_assets`` package (package data), or, in an
    editable install made before that package existed, the repository's ``frontend_assets`` folder."""
    try:
        from importlib.resources import files

        path = Path(str(files("frontend_assets")))
    except ModuleNotFoundError:
        path = Path(__file__).resolve().parents[3] / "frontend_assets"
    if not (path / "index.html").is_file():
        log.error("the dashboard's files are missing from %s", path)
    return path


ASSETS_DIR = assets_dir()
ASSET_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}


def plotly_bundle() -> Path:
    """The plotly.js bundle that the installed ``plotly`` Python package ships (no CDN)."""
    import plotly

    return Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"


@router.get("/")
def dashboard() -> FileResponse:
    return FileResponse(ASSETS_DIR / "index.html", media_type="text/html")


@router.get("/assets/{name}")
def asset(name: str) -> FileResponse:
    """One file of the dashboard (the ES modules, the stylesheet) or the plotly.js bundle."""
    if name == "plotly.min.js":
        return FileResponse(plotly_bundle(), media_type="text/javascript")
    path = ASSETS_DIR / name
    if "/" in name or name.startswith(".") or path.suffix not in ASSET_TYPES or not path.is_file():
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no asset {name!r}")
    return FileResponse(path, media_type=ASSET_TYPES[path.suffix])
