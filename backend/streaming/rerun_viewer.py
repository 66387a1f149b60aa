"""The rerun web viewer of the server, and where runs stream live (product.md, "Live rerun").

:class:`RerunWebViewer` starts the web viewer that ships in rerun-sdk as a child process,
``rerun --serve-web --bind 127.0.0.1 --web-viewer-port P --port G``: the viewer's page on P and a
gRPC proxy on G, both on loopback only (``rr.serve_web_viewer`` would listen on 0.0.0.0:
stack-notes.md).  ``--server-memory-limit`` bounds what the proxy buffers for late viewers and
``--memory-limit`` what the viewer keeps: the oldest data is dropped first, so a long run cannot
exhaust either.  The child dies with the server (``PR_SET_PDEATHSIG``) and is stopped with it.

Runs stream live to :func:`live_url`: the ``--rerun-connect`` URL if one is set (another viewer or
proxy), else the viewer's own proxy.  Links: :meth:`RerunWebViewer.link` opens the viewer on a URL
(a finished run's ``.rrd`` over HTTP, or the live proxy).
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
from pathlib import Path
from typing import IO

log = logging.getLogger(__name__)


def rerun_binary() -> str:
    """The ``rerun`` executable that ships in rerun-sdk (``rerun_cli/rerun``), else the ``rerun`` on PATH.

    Not the environment's ``bin/rerun``: that is a Python wrapper that runs the executable as *its*
    child, so stopping (or killing) the wrapper would leave the viewer running.
    """
    try:
        import rerun_cli

        bundled = Path(rerun_cli.__file__).parent / "rerun"
        if bundled.exists():
            return str(bundled)
    except ImportError:
        pass
    here = Path(sys.executable).parent / "rerun"
    if here.exists():
        return str(here)
    found = shutil.which("rerun")
    if found is None:
        raise FileNotFoundError("the rerun CLI (rerun-sdk) is not installed")
    return found


def _die_with_parent() -> None:  # pragma: no cover - runs in the child
    try:
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def grpc_url(port: int, host: str = "127.0.0.1") -> str:
    return f"rerun+http://{host}:{port}/proxy"


def reachable(url: str, timeout: float = 0.3) -> bool:
    """A TCP connection to the URL's host and port succeeds (a rerun gRPC endpoint is listening)."""
    parsed = urllib.parse.urlparse(url)
    if parsed.hostname is None or parsed.port is None:
        return False
    try:
        with socket.create_connection((parsed.hostname, parsed.port), timeout=timeout):
            return True
    except OSError:
        return False


class RerunWebViewer:
    """``rerun --serve-web`` on loopback as a child process (module docstring)."""

    def __init__(self, web_port: int, grpc_port: int, *, server_memory_limit: str = "512MiB",
                 memory_limit: str = "2GiB", log_dir: Path | None = None) -> None:
        self.web_port, self.grpc_port = web_port, grpc_port
        self.server_memory_limit, self.memory_limit = server_memory_limit, memory_limit
        self.log_dir = log_dir
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        """The viewer's page."""
        return f"http://127.0.0.1:{self.web_port}/"

    @property
    def proxy_url(self) -> str:
        """Its gRPC proxy: where runs stream when no ``--rerun-connect`` is given."""
        return grpc_url(self.grpc_port)

    def link(self, data_url: str, page: str | None = None) -> str:
        """The viewer opened on ``data_url`` (an ``.rrd`` over HTTP, or a ``rerun+http://`` proxy); ``page`` is where
        the viewer is served (default: its own port; the server serves it offline at ``/rerun/``)."""
        return f"{page or self.url}?url={urllib.parse.quote(data_url, safe='')}"

    def start(self, timeout_s: float = 20.0) -> bool:
        """Start the child; True once its page answers (False, with a warning, if it cannot start)."""
        cmd = [rerun_binary(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(self.web_port),
               "--port", str(self.grpc_port), "--server-memory-limit", self.server_memory_limit,
               "--memory-limit", self.memory_limit]
        out: IO[bytes] | None = None
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            out = open(self.log_dir / "rerun-web-viewer.log", "ab")  # noqa: SIM115  # closed below
        env = {**os.environ, "RERUN_ANALYTICS": "0"}
        try:
            self.proc = subprocess.Popen(cmd, stdout=out if out is not None else subprocess.DEVNULL,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                         preexec_fn=_die_with_parent)  # noqa: PLW1509
        except OSError as exc:
            log.warning("rerun web viewer not started (%s): %s", " ".join(cmd), exc)
            return False
        finally:
            if out is not None:
                out.close()  # the child has its own descriptor
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                log.warning("rerun web viewer exited at once (status %s); is port %d or %d taken?",
                            self.proc.returncode, self.web_port, self.grpc_port)
                self.proc = None
                return False
            if reachable(self.url, 0.2) and reachable(self.proxy_url, 0.2):
                log.info("rerun web viewer on %s (gRPC proxy %s)", self.url, self.proxy_url)
                return True
            time.sleep(0.1)
        log.warning("rerun web viewer did not answer within %.0f s", timeout_s)
        return True

    def stop(self) -> None:
        p, self.proc = self.proc, None
        if p is None or p.poll() is not None:
            return
        p.terminate()
        try:
            p.wait(timeout=5)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)
