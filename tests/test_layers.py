"""The packages import downward only (docs/interfaces.md, "The layout"): scripts/layers.py on the repository.

A plain import is enough to break it (``twin`` importing ``backend``, ``twin.control`` importing
``twin.runs``, two modules importing each other), so the checker itself is tested on small files too.
"""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def layers(load_script):
    return load_script("layers")


def test_no_import_runs_against_the_layers(layers) -> None:
    bad = layers.wrong_way(layers.all_imports())
    assert not bad, "\n".join(f"{i.path}:{i.line} {i.module} -> {i.target} ({why})" for i, why in bad)


def test_no_two_modules_import_each_other(layers) -> None:
    known = [  # circles that remain (each one module cut in two); a new one fails
        ["twin.furnace.simulated.integrators", "twin.furnace.simulated.plant"],
        ["twin.radiation.cache", "twin.radiation.model"],
        ["twin.runs.metrics", "twin.runs.record"],
    ]
    cycles = layers.module_cycles(layers.all_imports())
    assert [c for c in cycles if c not in known] == []


def test_every_module_has_a_layer(layers) -> None:
    modules = {i.module for i in layers.all_imports()} | {i.target for i in layers.all_imports()}
    assert [m for m in sorted(modules) if not layers.package_of(m)] == []


def test_the_checker_sees_upward_sideways_and_circular_imports(layers, tmp_path, monkeypatch) -> None:
    for name, text in {
        "twin/__init__.py": "",
        "twin/config.py": "from twin.physics.fillet import FILLET_X\n",  # upward
        "twin/physics/__init__.py": "",
        "twin/physics/fillet.py": "def f():\n    from twin.config import X\n",  # lazy, downward: fine
        "twin/control/__init__.py": "",
        "twin/control/saturation.py": "import twin.estimation.ekf\n",  # sideways
        "twin/estimation/__init__.py": "",
        "twin/estimation/ekf.py": "from twin.estimation import joint\n",
        "twin/estimation/joint.py": "from twin.estimation.ekf import Estimator\n",  # circle with ekf
    }.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    monkeypatch.setattr(layers, "ROOT", tmp_path)
    imports = layers.all_imports()
    assert sorted((i.module, i.target, why.split(":")[0]) for i, why in layers.wrong_way(imports)) == [
        ("twin.config", "twin.physics.fillet", "upward"),
        ("twin.control.saturation", "twin.estimation.ekf", "sideways"),
    ]
    assert layers.module_cycles(imports) == [["twin.config", "twin.physics.fillet"],
                                             ["twin.estimation.ekf", "twin.estimation.joint"]]
