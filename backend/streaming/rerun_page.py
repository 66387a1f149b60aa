"""The rerun web viewer served by the server itself at ``/rerun/``, offline.

The viewer's files come from the ``rerun --serve-web`` child (:class:`backend.streaming.rerun_viewer.RerunWebViewer`)
and are kept in memory after their first request.  Its page asks Google for a font and, on rerun's own site, loads
an analytics script: both are removed from the page, and a Content-Security-Policy lets the viewer reach only this
server and the rerun gRPC endpoints the runs stream to (so nothing else is contacted, whatever the viewer's code
tries).  Served from the dashboard's origin, a run's recording (``/api/runs/<id>/recording.rrd``: the viewer needs
the ``.rrd`` ending to open a file) is read without any cross-origin rule.
"""

from __future__ import annotations

import re
import threading
import urllib.parse

import httpx

#: the page's requests to other sites: Google's font (preconnects and stylesheet) and rerun's analytics script
_EXTERNAL = [
    re.compile(r'<link[^>]*href="https://fonts\.(googleapis|gstatic)\.com[^"]*"[^>]*/?>\s*', re.S),
    re.compile(r'<link\s+href="https://fonts\.googleapis\.com[^"]*"\s+rel="stylesheet"\s*/>\s*', re.S),
    re.compile(r'if \(window\.location\.hostname == "app\.rerun\.io"\) \{.*?document\.body\.appendChild\(script\);'
               r"\s*\}\s*", re.S),
]


def offline_page(html: str) -> str:
    """The viewer's ``index.html`` without its requests to other sites.

    >>> offline_page('<link rel="preconnect" href="https://fonts.gstatic.com" crossorigin />\\n<title>x</title>')
    '<title>x</title>'
    """
    for pattern in _EXTERNAL:
        html = pattern.sub("", html)
    return html


def origin_of(url: str) -> str | None:
    """``http://host:port`` of a ``rerun+http://`` (or http) URL, as the viewer connects to it.

    >>> origin_of("rerun+http://127.0.0.1:9876/proxy")
    'http://127.0.0.1:9876'
    """
    p = urllib.parse.urlparse(url.removeprefix("rerun+"))
    if p.scheme not in ("http", "https") or not p.hostname:
        return None
    return f"{p.scheme}://{p.hostname}" + (f":{p.port}" if p.port else "")


def content_security_policy(grpc_urls: list[str]) -> str:
    """Only this server, inline scripts and styles of the page, WebAssembly, and the gRPC endpoints of the runs."""
    connect = " ".join(sorted({o for o in map(origin_of, grpc_urls) if o}))
    return ("default-src 'self'; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'; "
            "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
            f"connect-src 'self' {connect}".rstrip() + "; worker-src 'self' blob:; object-src 'none'; "
            "base-uri 'self'; frame-ancestors 'self'")


class ViewerFiles:
    """The viewer's files from its child's web port, fetched once each."""

    def __init__(self, web_port: int) -> None:
        self.base = f"http://127.0.0.1:{web_port}/"
        self._files: dict[str, tuple[bytes, str]] = {}
        self._lock = threading.Lock()

    def get(self, path: str) -> tuple[bytes, str] | None:
        """(content, media type) of ``path`` ('' is the page), or ``None`` if the viewer has no such file."""
        path = path or "index.html"
        if ".." in path.split("/"):
            return None
        with self._lock:
            known = self._files.get(path)
        if known is not None:
            return known
        r = httpx.get(self.base + urllib.parse.quote(path), timeout=60.0)
        if r.status_code != 200:
            return None
        media = r.headers.get("content-type", "application/octet-stream")
        body = offline_page(r.text).encode() if path == "index.html" else r.content
        with self._lock:
            self._files[path] = (body, media)
        return body, media
