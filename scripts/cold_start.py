"""Cold starts of the server, as a new user's first ``furnace-twin serve``: an empty radiation cache each time.

Each start gets its own empty cache (``FURNACE_TWIN_CACHE``) and data directory and free ports; the script polls
``GET /api/health`` every 0.5 s and reports when the server first answered, when the radiation models were
ready, or what failed (the health's reason), or that the progress (stage and positions) did not move for
``--stuck`` seconds (a hang: the last health answer is printed), or that it was still progressing at
``--timeout`` (slow, not hung).  Issue 27: 2 of 5 cold starts hung forever with 0/0 positions.

    python scripts/cold_start.py --repeat 3 [--config small] [--stuck 300] [--timeout 3600]

One line per start; exits 1 unless every start was ready.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def health(port: int) -> dict[str, Any] | None:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/health", timeout=2.0) as r:
            body: dict[str, Any] = json.loads(r.read())
            return body
    except OSError:
        return None


def cold_start(config: str | None, timeout: float, stuck: float, keep: bool) -> tuple[str, str]:
    """One cold start: (outcome, one-line description)."""
    root = Path(tempfile.mkdtemp(prefix="furnace-cold-start-"))
    port = free_port()
    env = dict(os.environ, FURNACE_TWIN_CACHE=str(root / "cache"))
    cmd = [sys.executable, "-m", "furnace_twin.cli"]
    if config:
        cmd += ["--config", config]
    cmd += ["serve", "--port", str(port), "--viser-port", str(free_port()), "--rerun-web-port", "0",
            "--data-dir", str(root / "data")]
    log = open(root / "server.log", "wb")
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
    answered = None
    last: dict[str, Any] | None = None
    stages: list[str] = []
    moved = time.monotonic()
    try:
        while time.monotonic() - t0 < timeout:
            if proc.poll() is not None:
                return "exited", f"server exited with code {proc.returncode} (log {root / 'server.log'})"
            h = health(port)
            if h is not None:
                last = h
                if answered is None:
                    answered = time.monotonic() - t0
                p = h.get("radiation_progress") or {}
                stage = f"{p.get('stage')} {p.get('done')}/{p.get('total')}"
                if not stages or stages[-1] != stage:
                    stages.append(stage)
                    moved = time.monotonic()
                if h["radiation"] == "ready":
                    return "ready", (f"answered after {answered:.1f} s, ready after {time.monotonic() - t0:.1f} s "
                                     f"({len(stages)} progress states, first: {stages[0]!r})")
                if h["radiation"] == "failed":
                    return "failed", f"failed after {time.monotonic() - t0:.1f} s: {p.get('error')}"
            if time.monotonic() - moved > stuck:
                return "hung", f"no progress for {stuck:.0f} s; last health: {json.dumps(last)}"
            time.sleep(0.5)
        return "slow", f"still progressing after {timeout:.0f} s; last health: {json.dumps(last)}"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()
        if not keep:
            shutil.rmtree(root, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--config", default=None, help="furnace config (default: the default furnace)")
    ap.add_argument("--stuck", type=float, default=300.0, help="seconds without progress before a start counts as hung")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds before giving up on a start that progresses")
    ap.add_argument("--keep", action="store_true", help="keep each start's directory (cache, data, server.log)")
    args = ap.parse_args()
    outcomes = []
    for k in range(args.repeat):
        outcome, text = cold_start(args.config, args.timeout, args.stuck, args.keep)
        outcomes.append(outcome)
        sys.stdout.write(f"cold start {k + 1}/{args.repeat}: {outcome}: {text}\n")
        sys.stdout.flush()
    return 0 if all(o == "ready" for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
