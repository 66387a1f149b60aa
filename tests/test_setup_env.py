"""``scripts/setup-env.sh`` (run by ``serve.sh`` at every start) runs pip only when the environment is missing or
out of date (issue 27 item 9: it re-ran pip on every start, +10-14 s).  Run on a copy of the project's two input
files with a fake ``.venv/bin/python`` that logs what it is asked to do."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: stands in for the venv's interpreter: logs each call's arguments, fails the import check when told to
FAKE_PYTHON = """#!/usr/bin/env bash
echo "$*" >> "$(dirname "$0")/../calls.log"
if [ "$1" = "-c" ] && [ -f "$(dirname "$0")/../broken" ]; then exit 1; fi
exit 0
"""


def _project(tmp_path: Path) -> Path:
    (tmp_path / "scripts").mkdir()
    shutil.copy(ROOT / "scripts" / "setup-env.sh", tmp_path / "scripts" / "setup-env.sh")
    for name in ("pyproject.toml", "constraints.txt"):
        shutil.copy(ROOT / name, tmp_path / name)
    py = tmp_path / ".venv" / "bin" / "python"
    py.parent.mkdir(parents=True)
    py.write_text(FAKE_PYTHON)
    py.chmod(0o755)
    return tmp_path


def _setup(project: Path, **env: str) -> list[str]:
    log = project / ".venv" / "calls.log"
    log.unlink(missing_ok=True)
    subprocess.run(["bash", "scripts/setup-env.sh"], cwd=project, check=True, timeout=60,
                   env={"PATH": "/usr/bin:/bin", **env})
    return [line for line in log.read_text().splitlines() if line.startswith("-m pip")]


def test_pip_runs_only_when_the_environment_is_missing_or_out_of_date(tmp_path) -> None:
    project = _project(tmp_path)
    assert len(_setup(project)) == 2  # no stamp yet: pip upgrade + install
    assert _setup(project) == []  # installed from these files: nothing to do
    with (project / "constraints.txt").open("a") as f:
        f.write("# a pin changed\n")
    assert len(_setup(project)) == 2  # constraints changed: installs again
    assert _setup(project) == []
    assert len(_setup(project, FORCE_SETUP="1")) == 2
    # the stamp matches but a package went missing: pip runs, and a still failing import is reported, not stamped
    (project / ".venv" / "broken").touch()
    (project / ".venv" / "calls.log").unlink()
    res = subprocess.run(["bash", "scripts/setup-env.sh"], cwd=project, timeout=60, capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin"})
    assert res.returncode == 1 and "the environment is incomplete" in res.stderr, res
    assert "-m pip install -q -c constraints.txt" in (project / ".venv" / "calls.log").read_text()
    (project / ".venv" / "broken").unlink()
    assert len(_setup(project)) == 2  # no stamp was written: installs again
    assert _setup(project) == []
