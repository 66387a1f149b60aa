"""Values as JSON: the one place where NaN and inf become ``null``.

A metric whose window the run did not reach is NaN, a gated thermocouple reads NaN; JSON has no NaN
(``json.dumps`` would write the non-standard ``NaN`` token, which browsers and ``jq`` refuse).  Every file,
record and HTTP body of a run passes its numbers through :func:`jsonable` (or :func:`finite_or_none` for one
number).

>>> jsonable({"a": float("nan"), "b": [1, float("inf"), 2.5], "c": None})
{'a': None, 'b': [1, None, 2.5], 'c': None}
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def finite_or_none(x: Any) -> float | None:
    """One number as a JSON float: NaN, inf (a gated or missing TC, an unreached window) and ``None`` (no
    truth) become ``None``."""
    if x is None:
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def jsonable(obj: Any) -> Any:
    """Recursively turn numpy scalars / arrays, tuples and non-finite floats into plain JSON values
    (dict keys become strings); other values are returned as they are."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return finite_or_none(obj)
    return obj
