"""The run record keeps fields at every sample through the metrics' windows, then one per second:
what a long run holds in memory grows by about 3.5 kB per simulated second, not per sample."""

from __future__ import annotations

import numpy as np

from twin.runs.metrics import compute_metrics
from twin.runs.record import RunHeader, RunRecord, Snapshot


def _record(**kw) -> RunRecord:
    h = RunHeader(x=np.linspace(0.05, 0.35, 4), y=np.linspace(0.05, 0.15, 3), tc_positions=np.full((4, 2), 0.1),
                  L_s=0.4, W_s=0.2, t_E=2.0, setpoint=1000.0, group_names=("a",), scenario="{}")
    return RunRecord(h, **kw)


def _snap(j: int, t_s: float = 0.1) -> Snapshot:
    field = np.full((3, 4), 900.0 + j)
    return Snapshot(j=j, t=round(j * t_s, 9), eta=0.0, T_ref=1000.0, T_mean_hat=900.0 + j, field_hat=field,
                    field_true=field + 1.0, tc=np.zeros(4), tc_hat=np.zeros(4), u=np.zeros(1), u_ff=np.zeros(1),
                    inhomogeneity=0.0, true_mean=901.0 + j, true_inhomogeneity=0.0, events=())


def test_fields_every_sample_then_every_kth() -> None:
    rec = _record(field_every=10, full_rate_until=4.0)  # 4 s = 2 t_E
    for j in range(101):  # 0 .. 10 s at t_s = 0.1 s
        rec.append(_snap(j))
    a = rec.arrays()
    assert len(a["t"]) == 101
    # 0.0 .. 4.0 s: 41 samples; then 5.0, 6.0, ..., 10.0 s (every 10th sample after the last one kept)
    expected = [round(0.1 * j, 9) for j in range(41)] + [5.0, 6.0, 7.0, 8.0, 9.0, 10.0]
    np.testing.assert_allclose(a["t_field"], expected)
    assert a["field_hat"].shape == (len(expected), 3, 4) and a["field_true"].shape == a["field_hat"].shape
    # each kept field is the one of its own sample
    np.testing.assert_allclose(a["field_hat"][:, 0, 0], 900.0 + np.round(np.asarray(expected) / 0.1))


def test_a_record_sized_for_its_run_never_reallocates() -> None:
    """capacity_for covers the run's samples and fields (here 101 and 47, as counted above), so the arrays
    reserved at the first sample are the ones written to the end: the memory grows with the data, not by
    doubled buffers; a sample beyond the estimate still fits."""
    cap = RunRecord.capacity_for(101, 0.1, 10, 4.0)
    assert cap[0] == 101 and 47 <= cap[1] <= 48
    rec, ref = _record(field_every=10, full_rate_until=4.0, capacity=cap), _record(field_every=10, full_rate_until=4.0)
    rec.append(_snap(0))
    buffers = {k: c._data for k, c in {**rec._columns, **rec._fields}.items()}
    ref.append(_snap(0))
    for j in range(1, 101):
        rec.append(_snap(j))
        ref.append(_snap(j))
    assert all(c._data is buffers[k] for k, c in {**rec._columns, **rec._fields}.items())
    rec.append(_snap(101))
    ref.append(_snap(101))
    a, b = rec.arrays(), ref.arrays()
    assert set(a) == set(b)
    for k in b:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_metrics_unchanged_within_the_windows() -> None:
    full, thin = _record(), _record(field_every=10, full_rate_until=4.0)
    for j in range(41):
        full.append(_snap(j))
        thin.append(_snap(j))
    np.testing.assert_equal(compute_metrics(full.arrays()), compute_metrics(thin.arrays()))


def test_tails_of_a_thinned_record_add_up_to_its_arrays() -> None:
    """The parts a running server appends (twin.runs.series_store) hold each kept field once, in order."""
    rec = _record(field_every=10, full_rate_until=4.0)
    parts = []
    start = 0
    for j in range(101):
        rec.append(_snap(j))
        if j % 7 == 6 or j == 100:  # a flush now and then
            parts.append(rec.tail(start))
            start = len(rec)
    whole = rec.arrays()
    for k in ("t", "T_mean_hat", "t_field", "field_hat", "field_true"):
        np.testing.assert_array_equal(np.concatenate([p[k] for p in parts]), whole[k])
