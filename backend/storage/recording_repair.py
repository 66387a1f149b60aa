"""A recording cut short by a crash, made readable again.

rerun writes the footer (the manifests) of an ``.rrd`` file when the recording is closed; a server
killed during a run leaves a file without it, which ``rerun rrd verify`` refuses.  rerun's own
``rrd merge --continue-on-error`` reads such a file up to its last complete message and writes a
complete one: the recovery (``backend/storage/recovery.py``) replaces the file with that.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

log = logging.getLogger(__name__)

TIMEOUT_S = 120.0


def rerun_cli() -> str | None:
    """The ``rerun`` command of this environment (the rerun-sdk wheel's), else one on PATH."""
    here = Path(sys.executable).parent / "rerun"
    return str(here) if here.is_file() else shutil.which("rerun")


def verified(path: Path, cli: str) -> bool:
    out = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=TIMEOUT_S)
    return out.returncode == 0 and "without error" in (out.stdout + out.stderr)


def repair_recording(path: Path) -> bool:
    """Rewrite ``path`` so it verifies; True if it does now (or did already)."""
    cli = rerun_cli()
    if cli is None or not path.is_file():
        return False
    try:
        if verified(path, cli):
            return True
        tmp = path.with_name(path.name + ".repaired.rrd")
        subprocess.run([cli, "rrd", "merge", "--continue-on-error", str(path), "-o", str(tmp)],
                       capture_output=True, text=True, timeout=TIMEOUT_S, check=True)
        if not verified(tmp, cli):
            tmp.unlink(missing_ok=True)
            return False
        os.replace(tmp, path)
        return True
    except (OSError, subprocess.SubprocessError) as exc:
        log.warning("cannot repair %s: %s", path, exc)
        return False
