"""Are two runs' results the same?  ``python -m benchmarks.compare_runs DIR_A DIR_B`` (issue 21: a change for
speed must leave a run's results unchanged).

Compares ``metrics.json`` value by value (NaN, stored as null, equal to itself) and every array of
``timeseries.npz`` byte for byte (dtype, shape and ``tobytes``: NaN payloads and the sign of zero count), and
prints what differs; exit status 0 if nothing does, 1 otherwise.  The figures are not compared (PNG bytes
depend on the matplotlib build; ``cmp`` them if both were drawn by the same one).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def differences(a: Path, b: Path) -> list[str]:
    """What differs between the runs in folders ``a`` and ``b`` (empty: the same results)."""
    out: list[str] = []
    ma = json.loads((a / "metrics.json").read_text())
    mb = json.loads((b / "metrics.json").read_text())
    out += [f"metric {k}: only in one" for k in sorted(set(ma) ^ set(mb))]
    out += [f"metric {k}: {ma[k]!r} != {mb[k]!r}" for k in sorted(set(ma) & set(mb)) if ma[k] != mb[k]]
    with np.load(a / "timeseries.npz") as za, np.load(b / "timeseries.npz") as zb:
        out += [f"array {k}: only in one" for k in sorted(set(za.files) ^ set(zb.files))]
        for k in sorted(set(za.files) & set(zb.files)):
            x, y = za[k], zb[k]
            if x.dtype != y.dtype or x.shape != y.shape:
                out.append(f"array {k}: {x.dtype}{x.shape} != {y.dtype}{y.shape}")
            elif x.tobytes() != y.tobytes():
                out.append(f"array {k}: values differ")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2:
        print("usage: python -m benchmarks.compare_runs DIR_A DIR_B", file=sys.stderr)  # noqa: T201
        return 2
    found = differences(Path(args[0]), Path(args[1]))
    for line in found:
        print(line)  # noqa: T201
    if not found:
        print("the same: metrics.json and every array of timeseries.npz")  # noqa: T201
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
