"""``python -m benchmarks.compare_runs``: two runs the same only when every metric and every array's bytes are."""

from __future__ import annotations

import json

import numpy as np

from benchmarks.compare_runs import differences, main
from twin.runs.record import save_arrays


def _run(folder, field, metrics):
    folder.mkdir()
    (folder / "metrics.json").write_text(json.dumps(metrics))
    save_arrays(folder / "timeseries.npz", {"t": np.arange(3) * 0.1, "field_hat": field, "event_text": np.array(["a"])})
    return folder


def test_the_same_runs_and_each_kind_of_difference(tmp_path) -> None:
    field = np.array([[1.0, np.nan], [0.0, 2.0]], np.float32)
    a = _run(tmp_path / "a", field, {"mean_error_steady_max": 0.001, "nees_mean": None})
    assert differences(a, _run(tmp_path / "b", field.copy(), {"mean_error_steady_max": 0.001, "nees_mean": None})) == []
    assert main([str(a), str(tmp_path / "b")]) == 0
    negative_zero = field.copy()
    negative_zero[1, 0] = -0.0  # equal as a float, not as bytes: a reordered sum can do this
    c = _run(tmp_path / "c", negative_zero, {"mean_error_steady_max": 0.0010000000000000002, "nees_mean": None})
    assert differences(a, c) == ["metric mean_error_steady_max: 0.001 != 0.0010000000000000002",
                                 "array field_hat: values differ"]
    d = _run(tmp_path / "d", field.astype(np.float64), {"mean_error_steady_max": 0.001})
    assert differences(a, d) == ["metric nees_mean: only in one", "array field_hat: float32(2, 2) != float64(2, 2)"]
    assert main([str(a), str(d)]) == 1
