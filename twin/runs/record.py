"""The run record: one run's samples as a time series, with save and load (product.md, ``timeseries.npz``).

A :class:`Snapshot` is one sample of a closed-loop run; a :class:`RunRecord` collects them in
growing arrays and writes them in the ``timeseries.npz`` layout:

* per sample (n,): ``t`` (s), ``eta`` (m), ``T_ref``, ``T_mean_hat`` (K), ``tc``, ``tc_hat`` (n, 4) K,
  ``u``, ``u_ff`` (n, 6) fractions of u_max; ``tc_status`` (n, 4) int8, :data:`TC_STATUS_CODES` of each
  reading (0 good, 1 bad, 2 missing: late or lost);
* fields at ``t_field``: ``field_hat`` (m, N_y, N_x) K, and ``field_true`` only when the furnace is a
  simulation (a real furnace has no true field).  Every sample up to ``full_rate_until`` (the loop: 2 t_E,
  the end of the metrics' windows, moved by a live reference change), then every ``field_every``-th (the
  loop: one per second, the least product.md allows), so a long run's memory grows by the scalars and
  about 3.5 kB per second;
* the estimate's uncertainty (issue 25): ``field_sigma`` (m, N_y, N_x) K beside ``field_hat``, ``sigma_mean``
  (n,) K (of the fillet mean), ``nis`` (n,) and, with a true field, ``nees`` (n,) (:mod:`twin.runs.consistency`);
* with a calibrating estimator: ``parameters``, ``parameter_sigma`` (n, 3) relative deviations (lamp
  efficiency, emissivity, convection; NaN where not calibrated); with a shadow estimator:
  ``shadow_T_mean_hat`` (n,), ``shadow_tc_hat`` (n, 4), ``shadow_field_hat`` (m, N_y, N_x);
* events: ``event_t`` (s), ``event_text`` and ``event_level`` (``info``, ``warn`` or ``error``), the
  run's own reports (re-plans, switches; the server adds its own: start, end, changes, saturation);
* live changes: ``change_t`` (s, the first sample that uses the change), ``change_kind``
  (``reference`` or ``oscillation``) and ``change_json`` (the new reference / oscillation as JSON); the
  metrics' windows start at the last reference change (:func:`twin.runs.metrics.windows_of`); these and
  the events are :class:`twin.events.RunEvent` and :class:`twin.events.RunChange`;
* the run's constants: ``x`` (N_x), ``y`` (N_y) cell centres in m, ``tc_positions`` (4, 2) m,
  ``L_s``, ``W_s`` m, ``t_E`` s, ``setpoint`` K, ``group_names``, ``scenario`` (JSON).

This module (with :mod:`twin.events` for the events' and changes' keys) is the only place that
names these keys; the loop, the metrics, the figures, the backend's flushes and recovery and the 3D view
read and write runs through it.

Example
-------
>>> import numpy as np
>>> from twin.events import load_changes
>>> rec = RunRecord(RunHeader(x=np.arange(3.0), y=np.arange(2.0), tc_positions=np.zeros((4, 2)), L_s=3.0,
...                           W_s=2.0, t_E=1.0, setpoint=1000.0, group_names=("a",), scenario="{}"),
...                 has_truth=False)   # e.g. a real furnace
>>> rec.append(Snapshot(j=0, t=0.0, eta=0.0, T_ref=300.0, T_mean_hat=301.0, field_hat=np.zeros((2, 3)),
...                     field_true=None, tc=np.zeros(4), tc_hat=np.zeros(4), u=np.zeros(1), u_ff=np.zeros(1),
...                     inhomogeneity=1.0, true_mean=None, true_inhomogeneity=None, events=("started",)))
>>> a = rec.arrays()
>>> rec.note_change(0.1, "reference", '{"setpoint": 900.0, "t_E": 5.0}')
>>> len(rec), a["T_mean_hat"].tolist(), "field_true" in a, a["event_text"].tolist()
(1, [301.0], False, ['started'])
>>> rec.arrays()["change_kind"].tolist(), load_changes(rec.arrays())[0].body["setpoint"]
(['reference'], 900.0)
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.events import RunChange, RunEvent, change_arrays, event_arrays

Array = NDArray[np.float64]

#: per-sample series of a Snapshot that the record keeps (its attribute names), and the field series
SAMPLE_SERIES = ("t", "eta", "T_ref", "T_mean_hat", "tc", "tc_hat", "u", "u_ff")
FIELD_SERIES = ("field_hat", "field_true", "shadow_field_hat", "field_sigma")
#: series a run has only with the matching estimator: calibrated parameters (relative deviations in the
#: order of twin.model.tables.PARAMETERS, NaN where not calibrated), a shadow estimator's outputs, and the
#: estimate's uncertainty (twin.estimation.uncertainty: ``field_sigma`` K, ``sigma_mean`` K of the fillet
#: mean, ``nis`` per reading, ``nees`` per fillet cell: twin.runs.consistency; ``nees`` needs a true field)
OPTIONAL_SERIES = ("parameters", "parameter_sigma", "shadow_T_mean_hat", "shadow_tc_hat", "shadow_field_hat",
                   "field_sigma", "sigma_mean", "nis", "nees")
#: ``tc_status`` codes of the reading statuses of :class:`twin.furnace.interface.Readings`
TC_STATUS_CODES = {"good": 0, "bad": 1, "missing": 2, "unlinked": 3}


@dataclass(frozen=True)
class Snapshot:
    """One sample of a run (all temperatures in K, powers as fractions of u_max).

    ``field_true``, ``true_mean`` and ``true_inhomogeneity`` are ``None`` for a furnace without a
    true field (a real one).
    """

    j: int
    t: float
    eta: float
    T_ref: float
    T_mean_hat: float
    field_hat: Array  # (N_y, N_x) estimate at the FD cell centres
    field_true: Array | None  # (N_y, N_x) the simulated furnace's state
    tc: Array  # (4,) readings TC1..TC4 (NaN where a reading is missing)
    tc_hat: Array  # (4,) estimate at xi_1..xi_4
    u: Array  # (6,) applied group powers
    u_ff: Array  # (6,) feedforward part
    inhomogeneity: float  # T_sup(t) of the estimate, K
    true_mean: float | None
    true_inhomogeneity: float | None
    events: tuple[str, ...] = ()
    parameters: Array | None = None  # (3,) calibrated deviations (lamp efficiency, emissivity, convection)
    parameter_sigma: Array | None = None  # (3,) their standard deviations
    shadow_T_mean_hat: float | None = None  # the shadow estimator's fillet mean, TCs and field
    shadow_tc_hat: Array | None = None
    shadow_field_hat: Array | None = None
    tc_status: tuple[str, ...] = ()  # "good" / "bad" / "missing" / "unlinked" per TC; () = all good
    late_samples: int = 0  # samples of the run so far with a reading that did not come in time
    blind_since: float | None = None  # run time since which no TC reading reached the estimate (degraded)
    field_sigma: Array | None = None  # (N_y, N_x) standard deviation of field_hat, K
    sigma_mean: float | None = None  # standard deviation of T_mean_hat, K
    nis: float | None = None  # normalised innovation squared per TC reading used (1 when consistent)
    nees: float | None = None  # mean over the fillet of ((field_hat - field_true) / field_sigma)^2


@dataclass(frozen=True)
class StoredSnapshot(Snapshot):
    """A :class:`Snapshot` read back from a saved run; ``has_field`` is False when the file held no
    estimated field of the grid (the field is then the last fillet mean everywhere)."""

    has_field: bool = True


@dataclass(frozen=True)
class RunHeader:
    """What does not change during a run (the record's constants)."""

    x: Array
    y: Array
    tc_positions: Array
    L_s: float
    W_s: float
    t_E: float
    setpoint: float
    group_names: tuple[str, ...]
    scenario: str
    #: a simulated furnace's true fillet mean (K) at the samples from the start with every lamp off
    #: (``SimulatedFurnace.lamps_off_means``; the metric ``true_mean_lead_lamps_off_max``), ``None`` for a furnace
    #: that cannot be left alone (a real one)
    true_mean_lamps_off: Array | None = None

    def arrays(self) -> dict[str, Any]:
        out: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        out["group_names"] = np.asarray(self.group_names)
        if self.true_mean_lamps_off is None:
            del out["true_mean_lamps_off"]
        return out

    @classmethod
    def from_arrays(cls, a: Mapping[str, Any]) -> RunHeader:
        return cls(
            x=np.asarray(a["x"], float), y=np.asarray(a["y"], float),
            tc_positions=np.asarray(a["tc_positions"], float).reshape(-1, 2) if "tc_positions" in a
            else np.full((4, 2), np.nan),
            L_s=float(a["L_s"]), W_s=float(a["W_s"]), t_E=float(a["t_E"]), setpoint=float(a["setpoint"]),
            group_names=tuple(str(g) for g in np.asarray(a["group_names"]).ravel()) if "group_names" in a else (),
            scenario=str(a["scenario"]) if "scenario" in a else "{}",
            true_mean_lamps_off=np.asarray(a["true_mean_lamps_off"], float) if "true_mean_lamps_off" in a else None,
        )


class _Column:
    """A growing array (amortised doubling), read without copying the unused tail.

    The doubled buffer is allocated empty and only the samples so far are copied into it, so its unused
    half stays untouched and takes no memory until it is written (copying the whole old buffer next to
    an empty one, as ``np.concatenate`` does, touched it: a 1 h run's fields grew by 15 MB in one step).
    """

    def __init__(self, shape: tuple[int, ...], dtype: Any, capacity: int = 64) -> None:
        self._data = np.empty((max(64, int(capacity)), *shape), dtype)  # untouched until written
        self.n = 0

    def append(self, value: Any) -> None:
        if self.n == len(self._data):
            grown = np.empty((2 * len(self._data), *self._data.shape[1:]), self._data.dtype)
            grown[: self.n] = self._data
            self._data = grown
        self._data[self.n] = value
        self.n += 1

    def view(self) -> NDArray[Any]:
        return self._data[: self.n]


class RunRecord:
    """The samples of one run so far (append), as the ``timeseries.npz`` arrays (:meth:`arrays`).

    Parameters
    ----------
    header : the run's constants
    has_truth : the furnace reports a true field (a simulation); otherwise ``field_true`` is absent
    capacity : (samples, fields) the run is expected to keep: the arrays are reserved for them at once, so
        a run of known length grows its memory with its data and never by doubling a buffer (more
        samples than expected still fit, by doubling)
    """

    def __init__(self, header: RunHeader, *, has_truth: bool = True, field_every: int = 1,
                 full_rate_until: float = np.inf, capacity: tuple[int, int] = (64, 64)) -> None:
        self.header = header
        self.has_truth = has_truth
        self.field_every = max(1, int(field_every))
        self.full_rate_until = float(full_rate_until)
        self.capacity = capacity
        self._columns: dict[str, _Column] = {}
        self._fields: dict[str, _Column] = {}  # t_field and the field series
        self._since_field = 0
        self._optional: tuple[str, ...] = ()
        self._events: list[RunEvent] = []
        self._changes: list[RunChange] = []

    @staticmethod
    def capacity_for(n_samples: int, t_s: float, field_every: int, full_rate_until: float) -> tuple[int, int]:
        """(samples, fields) a run of ``n_samples`` keeps without live changes: a field at every sample up to
        ``full_rate_until`` (s), then one every ``field_every`` samples (an upper bound, by one field)."""
        n_full = min(n_samples, int(np.floor(full_rate_until / t_s + 1e-9)) + 1)
        return n_samples, n_full + (n_samples - n_full) // max(1, field_every) + 1

    def __len__(self) -> int:
        return self._columns["t"].n if self._columns else 0

    def append(self, snap: Snapshot) -> None:
        """Add one sample (its events too)."""
        values: dict[str, Any] = {k: getattr(snap, k) for k in SAMPLE_SERIES}
        values["tc_status"] = [TC_STATUS_CODES[st] for st in snap.tc_status] if snap.tc_status else [0] * len(snap.tc)
        if self.has_truth and snap.field_true is None:
            raise ValueError("this record keeps a true field, the snapshot has none")
        if not self._columns:  # the first sample decides which optional series the run has
            self._optional = tuple(k for k in OPTIONAL_SERIES if getattr(snap, k) is not None)
        for k in self._optional:
            v = getattr(snap, k)
            if v is None:
                raise ValueError(f"this record keeps {k}, the snapshot has none")
            if k not in FIELD_SERIES:  # the fields are kept below, thinned like the others
                values[k] = v
        if not self._columns:
            for k, v in values.items():
                self._columns[k] = _Column(np.shape(v), np.int8 if k == "tc_status" else float, self.capacity[0])
        for k, v in values.items():
            self._columns[k].append(v)
        self._since_field += 1
        if float(snap.t) <= self.full_rate_until or self._since_field >= self.field_every or not self._fields:
            self._since_field = 0
            fields_now: dict[str, Any] = {"t_field": snap.t, "field_hat": snap.field_hat}
            if self.has_truth:
                fields_now["field_true"] = snap.field_true
            for k in self._optional:
                if k in FIELD_SERIES:  # a shadow estimator's field
                    fields_now[k] = getattr(snap, k)
            if not self._fields:
                for k, v in fields_now.items():
                    self._fields[k] = _Column(np.shape(v), np.float32 if k in FIELD_SERIES else float,
                                              self.capacity[1])
            for k, v in fields_now.items():
                self._fields[k].append(v)
        self._events.extend(RunEvent.said(float(snap.t), str(e)) for e in snap.events)

    def note_change(self, t: float, kind: str, body_json: str) -> None:
        """Record a live change (``ClosedLoop.set_reference`` / ``set_oscillation``) that applies from ``t``;
        a reference change moves the metrics' windows, and the fields are kept at every sample through them."""
        change = RunChange(float(t), kind, json.loads(body_json))
        self._changes.append(change)
        if kind == "reference" and np.isfinite(self.full_rate_until):
            from twin.runs.metrics import windows_from

            w = windows_from(self.header.t_E, self.header.setpoint, [(change.t, change.kind, change.body)])
            self.full_rate_until = max(self.full_rate_until, w.steady[1])

    def arrays(self) -> dict[str, Any]:
        """Everything recorded so far, in the ``timeseries.npz`` layout (copies)."""
        h = self.header
        out = h.arrays()
        n_y, n_x = len(h.y), len(h.x)
        for k in SAMPLE_SERIES:
            col = self._columns.get(k)
            out[k] = col.view().copy() if col is not None else np.zeros(0)
        col = self._columns.get("tc_status")
        out["tc_status"] = col.view().copy() if col is not None else np.zeros((0, 4), np.int8)
        for k in FIELD_SERIES:
            if (k == "field_true" and not self.has_truth) or (k in OPTIONAL_SERIES and k not in self._optional):
                continue
            col = self._fields.get(k)
            out[k] = col.view().copy() if col is not None else np.zeros((0, n_y, n_x), np.float32)
        for k in self._optional:
            if k not in FIELD_SERIES:
                out[k] = self._columns[k].view().copy()
        t_field = self._fields.get("t_field")
        out["t_field"] = t_field.view().copy() if t_field is not None else np.zeros(0)
        out.update(event_arrays(self._events))
        out.update(change_arrays(self._changes))
        return out

    def add_event(self, event: RunEvent) -> None:
        """An event that is not a sample's (the server's: the start, refused changes, saturated groups, the end)."""
        self._events.append(event)

    @property
    def n_events(self) -> int:
        return len(self._events)

    @property
    def n_changes(self) -> int:
        return len(self._changes)

    def tail(self, start: int, events_from: int | None = None, changes_from: int = 0) -> dict[str, Any]:
        """The series of samples ``start``.. (per-sample arrays, ``t_field``), the events from index
        ``events_from`` on (default: those at or after the first of these samples) and the changes from
        ``changes_from`` on, without the run's constants: one part of an append-only store
        (:mod:`twin.runs.series_store`); the parts concatenated after the header give :meth:`arrays`."""
        n_y, n_x = len(self.header.y), len(self.header.x)
        out: dict[str, Any] = {}
        for k, col in self._columns.items():
            out[k] = col.view()[start:].copy()
        for k in SAMPLE_SERIES:
            out.setdefault(k, np.zeros(0))
        out.setdefault("tc_status", np.zeros((0, 4), np.int8))
        t0 = float(out["t"][0]) if len(out["t"]) else np.inf
        t_field = self._fields.get("t_field")
        if t_field is not None:  # the fields kept from sample ``start`` on (a subsequence of the samples)
            first = int(np.searchsorted(t_field.view(), t0 - 1e-9))
            for k, col in self._fields.items():
                out[k] = col.view()[first:].copy()
        out.setdefault("t_field", np.zeros(0))
        for k in FIELD_SERIES:
            if (k == "field_true" and not self.has_truth) or (k in OPTIONAL_SERIES and k not in self._optional):
                continue
            out.setdefault(k, np.zeros((0, n_y, n_x), np.float32))
        if events_from is None:
            events = [e for e in self._events if e.t >= t0]
        else:
            events = self._events[events_from:]
        out.update(event_arrays(events))
        out.update(change_arrays(self._changes[changes_from:]))
        return out

    def metrics(self) -> dict[str, Any]:
        """The run metrics of product.md and ``late_samples`` (:func:`twin.runs.metrics.run_metrics`)."""
        from twin.runs.metrics import run_metrics

        return run_metrics(self.arrays())

    def save(self, path: str | os.PathLike[str], *, compress: bool = True) -> None:
        """Write :meth:`arrays` atomically (see :func:`save_arrays`)."""
        save_arrays(path, self.arrays(), compress=compress)


#: zlib level of a compressed ``timeseries.npz``.  A run's file is mostly float32 fields with noise in their
#: low bits, which deflate hardly shrinks: a default 240 s run's 13.4 MB of arrays became 9.26 MB at level 1
#: in 0.32 s and 9.24 MB at level 6 (``np.savez_compressed``'s, zlib's default) in 0.63 s (issue 21, one
#: quiet machine): level 1 halves the time for 0.2 % more bytes.  The arrays read back are the same either way.
NPZ_COMPRESSLEVEL = 1


def write_npy_member(zf: zipfile.ZipFile, name: str, value: Any, *, allow_pickle: bool = False) -> None:
    """``value`` as the member ``name.npy`` of an open ``.npz`` (zip) file, as ``np.savez`` writes it."""
    with zf.open(f"{name}.npy", mode="w", force_zip64=True) as member:
        np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=allow_pickle)


def save_arrays(path: str | os.PathLike[str], arrays: Mapping[str, Any], *, compress: bool = True) -> None:
    """Write a time series atomically (tmp file, fsync, rename): a reader or a crash never sees half a file.

    The file is an ``.npz`` as ``np.savez`` / ``np.savez_compressed`` write it (one ``.npy`` member per key),
    compressed at :data:`NPZ_COMPRESSLEVEL`; ``compress=False`` for frequent rewrites of a growing run (the
    backend's flush every 2 s) and the parts of a run in progress.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp.npz")
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with open(tmp, "wb") as fh:
        with zipfile.ZipFile(fh, mode="w", compression=method, allowZip64=True,
                             compresslevel=NPZ_COMPRESSLEVEL if compress else None) as zf:
            for k, v in arrays.items():
                write_npy_member(zf, k, v, allow_pickle=True)  # as np.savez
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, p)


def load_arrays(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A saved time series as a dict of arrays (raises ``OSError`` / ``ValueError`` if unreadable)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def last_snapshot(arrays: Mapping[str, Any]) -> StoredSnapshot | None:
    """The last sample of a saved run as a :class:`StoredSnapshot` (``None`` if it has none).

    Missing series (an older or partial file) become NaN; without a stored field the estimate
    is the last fillet mean everywhere.
    """
    if "t" not in arrays or not len(arrays["t"]):
        return None
    h = RunHeader.from_arrays(arrays)
    shape = (len(h.y), len(h.x))

    def last(key: str, n: int | None = None) -> Any:
        if key in arrays and len(arrays[key]):
            return np.asarray(arrays[key][-1], dtype=float)
        return np.full(n, np.nan) if n else float("nan")

    T_mean = float(last("T_mean_hat"))
    fh = arrays.get("field_hat")
    field = np.asarray(fh[-1], float) if fh is not None and len(fh) and fh.shape[1:] == shape else None
    ft = arrays.get("field_true")
    truth = np.asarray(ft[-1], float) if ft is not None and len(ft) and ft.shape[1:] == shape else None
    fs = arrays.get("field_sigma")
    sigma = np.asarray(fs[-1], float) if fs is not None and len(fs) and fs.shape[1:] == shape else None
    return StoredSnapshot(
        j=len(arrays["t"]) - 1, t=float(last("t")), eta=float(np.nan_to_num(last("eta"))), T_ref=float(last("T_ref")),
        T_mean_hat=T_mean, field_hat=field if field is not None else np.full(shape, T_mean), field_true=truth,
        tc=last("tc", 4), tc_hat=last("tc_hat", 4), u=last("u", 6), u_ff=last("u_ff", 6),
        inhomogeneity=float("nan"), true_mean=None, true_inhomogeneity=None, has_field=field is not None,
        field_sigma=sigma, sigma_mean=float(last("sigma_mean")) if "sigma_mean" in arrays else None,
    )
