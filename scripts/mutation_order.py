"""pytest plugin for mutation runs (``scripts/mutation.sh``): run the fastest tests first.

mutmut runs, for each mutant, every selected test that executes the mutated function and stops
at the first failure (``-x``).  Most mutants are killed by some test; running the tests in the
order of their measured duration (mutmut's own statistics, ``mutants/mutmut-stats.json``) lets
a killed mutant die on its cheapest test instead of after the slow ones.  Loaded only by the
mutation runs (``-p scripts.mutation_order`` in ``[tool.mutmut]``), never by the suite.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def pytest_collection_modifyitems(session: Any, config: Any, items: list[Any]) -> None:
    stats = Path("mutmut-stats.json")  # mutmut runs the tests inside ./mutants
    if not stats.exists():
        return
    try:
        duration = json.loads(stats.read_text()).get("duration_by_test", {})
    except (OSError, ValueError):
        return
    items.sort(key=lambda item: duration.get(item.nodeid, 1e9))
