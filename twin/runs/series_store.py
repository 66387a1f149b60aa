"""A run's time series on disk while it runs: appended in parts, consolidated at the end.

Rewriting the whole ``timeseries.npz`` at every flush (every 2 s) made a 3600 s run at speed max
write 1.1 GB for a 175 MB file.  Here each flush writes only the samples since the previous one:

* ``timeseries.parts/header.npz``: the run's constants (:class:`twin.runs.record.RunHeader`), once;
* ``timeseries.parts/part-000001.npz``, ...: :meth:`twin.runs.record.RunRecord.tail` of each flush,
  each written atomically (tmp file, fsync, rename), so a crash loses at most the flush in progress;
* at the end :func:`consolidate` writes ``timeseries.npz`` in the layout of product.md (the parts
  concatenated after the header, the same arrays as ``RunRecord.arrays()``) and removes the parts;
  after a crash the server's recovery does the same with what was flushed.  It holds one part in memory
  at a time (:func:`write_parts`), not the whole run: a 1 h run at speed max raised the server's memory by
  23 MB while it finished when all parts were loaded at once.

Bytes written over a run: about once its final size (plus one small header).

Example
-------
>>> import tempfile, numpy as np
>>> from twin.runs.record import RunHeader, RunRecord, Snapshot
>>> rec = RunRecord(RunHeader(x=np.arange(3.0), y=np.arange(2.0), tc_positions=np.zeros((4, 2)), L_s=3.0,
...                           W_s=2.0, t_E=1.0, setpoint=1000.0, group_names=("a",), scenario="{}"), has_truth=False)
>>> def snap(j):
...     return Snapshot(j=j, t=0.1 * j, eta=0.0, T_ref=300.0, T_mean_hat=300.0 + j, field_hat=np.zeros((2, 3)),
...                     field_true=None, tc=np.zeros(4), tc_hat=np.zeros(4), u=np.zeros(1), u_ff=np.zeros(1),
...                     inhomogeneity=1.0, true_mean=None, true_inhomogeneity=None, events=(f"e{j}",))
>>> folder = Path(tempfile.mkdtemp())
>>> store = SeriesStore(folder)
>>> for j in range(5):
...     rec.append(snap(j))
...     _ = store.append(rec)       # a flush after every sample
>>> consolidate(folder, folder / "timeseries.npz")["T_mean_hat"].tolist()
[300.0, 301.0, 302.0, 303.0, 304.0]
>>> sorted(p.name for p in folder.iterdir())
['timeseries.npz']
"""

from __future__ import annotations

import logging
import os
import shutil
import uuid
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from twin.runs.record import RunRecord, load_arrays, save_arrays, write_npy_member

log = logging.getLogger(__name__)

PARTS = "timeseries.parts"
HEADER = "header.npz"


def parts_dir(folder: Path) -> Path:
    return Path(folder) / PARTS


class SeriesStore:
    """Appends a growing :class:`RunRecord` to ``folder/timeseries.parts`` (module docstring)."""

    def __init__(self, folder: Path) -> None:
        self.dir = parts_dir(folder)
        self.written = 0  # samples stored so far
        self.events_written = 0  # events and live changes stored so far
        self.changes_written = 0
        self.parts = 0
        self.bytes_written = 0

    def append(self, record: RunRecord) -> int:
        """Store the samples, events and live changes added since the last call; returns the bytes written."""
        n, n_events, n_changes = len(record), record.n_events, record.n_changes
        if n <= self.written and n_events <= self.events_written and n_changes <= self.changes_written:
            return 0
        self.dir.mkdir(parents=True, exist_ok=True)
        before = self.bytes_written
        if self.parts == 0:
            self._save(self.dir / HEADER, record.header.arrays())
        self.parts += 1
        self._save(self.dir / f"part-{self.parts:06d}.npz",
                   record.tail(self.written, self.events_written, self.changes_written))
        self.written, self.events_written, self.changes_written = n, n_events, n_changes
        return self.bytes_written - before

    def _save(self, path: Path, arrays: dict[str, Any]) -> None:
        save_arrays(path, arrays, compress=False)
        self.bytes_written += path.stat().st_size


def append_series(store: SeriesStore | None, folder: Path, record: RunRecord) -> SeriesStore:
    """Append ``record``'s samples since the last call to the parts in ``folder``: with ``store`` if it writes
    there, else with a new one; returns the store to keep for the next call (a loop's ``append_series``)."""
    if store is None or store.dir != parts_dir(Path(folder)):
        store = SeriesStore(Path(folder))
    store.append(record)
    return store


def has_parts(folder: Path) -> bool:
    return (parts_dir(folder) / HEADER).is_file()


def _readable_parts(folder: Path) -> Iterator[dict[str, Any]]:
    """The stored parts' arrays, oldest first, up to the first that cannot be read (the flush a crash
    interrupted): the series end before it."""
    for part in sorted(parts_dir(folder).glob("part-*.npz")):
        try:
            arrays = load_arrays(part)
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            log.warning("%s is unreadable (%s): the series ends before it", part, exc)
            return
        yield arrays


def load_parts(folder: Path) -> dict[str, Any]:
    """The stored parts as one time series (the ``timeseries.npz`` arrays); a part that cannot be read (the
    flush a crash interrupted) ends the series there."""
    out = load_arrays(parts_dir(folder) / HEADER)
    series: dict[str, list[Any]] = {}
    for arrays in _readable_parts(folder):
        for k, v in arrays.items():
            series.setdefault(k, []).append(v)
    for k, chunks in series.items():
        out[k] = np.concatenate(chunks)
    return out


def write_parts(folder: Path, path: Path) -> None:
    """Write the parts as one uncompressed ``.npz`` at ``path`` (atomically, as
    :func:`twin.runs.record.save_arrays`): the same arrays as ``save_arrays(path, load_parts(folder))``, with
    one part in memory at a time.  Each part is read once; its numeric series are appended to raw files
    beside ``path``, each of which then becomes one ``.npy`` member (its header written for the rows it
    holds); the texts (events) are concatenated in memory, as ``load_parts`` does.  A part that cannot be
    read ends the series there (the flush a crash interrupted)."""
    p = Path(path)
    tmp = p.with_name(p.name + ".tmp.npz")
    raw_dir = p.with_name(p.name + ".raw")
    raw_dir.mkdir(parents=True, exist_ok=True)
    order: list[str] = []  # series in the order of first appearance, as load_parts
    raw: dict[str, tuple[Path, np.dtype[Any], tuple[int, ...], int]] = {}  # file, dtype, row shape, rows
    memory: dict[str, list[Any]] = {}
    try:
        for arrays in _readable_parts(folder):  # one flush's samples at a time: small
            for k, v in arrays.items():
                a = np.ascontiguousarray(v)
                if k not in order:
                    order.append(k)
                if k in raw and (a.dtype, a.shape[1:]) != raw[k][1:3]:  # unlike the earlier parts: in memory
                    file, dtype, row, _ = raw.pop(k)
                    memory[k] = [np.fromfile(file, dtype).reshape(-1, *row)]
                if k in memory or a.ndim == 0 or a.dtype.kind not in "biufc":
                    memory.setdefault(k, []).append(a)
                    continue
                file, dtype, row, rows = raw.get(k, (raw_dir / f"{order.index(k)}.raw", a.dtype, a.shape[1:], 0))
                with open(file, "ab") as f:
                    a.tofile(f)
                raw[k] = (file, dtype, row, rows + len(a))
        header = load_arrays(parts_dir(folder) / HEADER)
        with open(tmp, "wb") as fh:
            with zipfile.ZipFile(fh, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
                for name, value in header.items():
                    if name not in order:
                        write_npy_member(zf, name, value)
                for name in order:
                    if name in memory:
                        write_npy_member(zf, name, np.concatenate(memory.pop(name)))
                        continue
                    file, dtype, row, rows = raw[name]
                    with zf.open(name + ".npy", mode="w", force_zip64=True) as member:
                        np.lib.format.write_array_header_1_0(member, {
                            "descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                            "shape": (rows, *row)})
                        with open(file, "rb") as f:
                            shutil.copyfileobj(f, member, 1 << 20)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    finally:
        shutil.rmtree(raw_dir, ignore_errors=True)
        tmp.unlink(missing_ok=True)


def consolidate(folder: Path, path: Path, *, load: bool = True) -> dict[str, Any]:
    """Write ``path`` (``timeseries.npz``) from the parts (:func:`write_parts`) and remove them; returns the
    arrays read back from ``path`` (``load=False``: nothing, the server's way of finishing a run).  Without
    parts, returns what ``path`` holds (already consolidated; nothing if the run stored no sample)."""
    if not has_parts(folder):
        return load_arrays(path) if load and Path(path).is_file() else {}
    write_parts(folder, path)
    shutil.rmtree(parts_dir(folder), ignore_errors=True)
    return load_arrays(path) if load else {}


def snapshot_file(folder: Path, path: Path, tmp_dir: Path | None = None) -> Path:
    """A readable ``timeseries.npz`` of a run in progress: the consolidated file if there is one, else the
    parts so far written to a temporary file (the caller removes it)."""
    if not has_parts(folder):
        return path
    tmp = Path(tmp_dir or folder) / f".timeseries-{uuid.uuid4().hex}.npz"
    write_parts(folder, tmp)
    return tmp
