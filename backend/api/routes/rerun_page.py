"""``/rerun/``: the rerun web viewer from the dashboard's own origin, offline (:mod:`backend.streaming.rerun_page`)."""

from __future__ import annotations

import asyncio

import httpx
from fastapi import APIRouter, HTTPException, Request, status
from fastapi.responses import RedirectResponse, Response

from backend.streaming.rerun_page import ViewerFiles, content_security_policy

router = APIRouter(tags=["rerun"], include_in_schema=False)


@router.get("/rerun")
def rerun_root(request: Request) -> RedirectResponse:
    query = f"?{request.url.query}" if request.url.query else ""
    return RedirectResponse(f"/rerun/{query}", status_code=status.HTTP_307_TEMPORARY_REDIRECT)


@router.get("/rerun/{path:path}")
async def rerun_file(path: str, request: Request) -> Response:
    """A file of the rerun web viewer (its page for ``/rerun/``), with a policy that keeps it on this machine."""
    viewer = getattr(request.app.state, "rerun_viewer", None)
    if viewer is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, "this server runs no rerun web viewer (--rerun-web-port 0)")
    files: ViewerFiles | None = getattr(request.app.state, "rerun_files", None)
    if files is None:
        files = request.app.state.rerun_files = ViewerFiles(viewer.web_port)
    try:
        got = await asyncio.to_thread(files.get, path)
    except httpx.HTTPError as exc:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE,
                            f"the rerun web viewer does not answer: {exc}") from None
    if got is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the rerun web viewer has no {path!r}")
    body, media = got
    manager = request.app.state.manager
    grpc = [u for u in (viewer.proxy_url, getattr(manager, "live_url", None)) if u]
    return Response(body, media_type=media, headers={"Content-Security-Policy": content_security_policy(grpc),
                                                     "Cache-Control": "no-cache"})
