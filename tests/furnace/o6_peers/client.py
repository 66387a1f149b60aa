"""An independent OPC UA client (o6, open62541) looking at this project's servers as a SCADA or an integrator's
tool would: by browse name, with its own type handling, subscriptions and writes.  It prints one line
``RESULT {json}`` with what it saw (the test process judges it: tests/furnace/test_o6_interop.py).

Run as a script (o6 ends its process ten minutes after ``import o6``)::

    python client.py emulator opc.tcp://127.0.0.1:4840/furnace-twin/
    python client.py results opc.tcp://127.0.0.1:4841/furnace-twin/results/ [--seconds 2]
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

RESULTS = ("RunId", "Status", "T", "T_ref", "T_mean_hat", "T_sup_hat", "TC4Error", "FieldSigmaMean",
           "LampEfficiency", "Emissivity", "FieldMin", "FieldMax")


def _name(status: Any) -> str:
    return getattr(status, "name", None) or str(status)


def _plain(v: Any) -> Any:
    if v is None or isinstance(v, bool | str):
        return v
    try:
        return float(v) if not isinstance(v, int) or isinstance(v, bool) else int(v)
    except (TypeError, ValueError):
        return str(v)


def child(node: Any, path: str) -> Any:
    """A node by browse names below ``node`` (o6's object tree: each level an attribute)."""
    for name in path.split("/"):
        node = getattr(node, name)
    return node


def _data_value(client: Any, node: Any) -> dict[str, Any]:
    dv = client.read(node, valueOnly=False)
    status = "GOOD" if not dv.status else _name(dv.status)  # an unset status is Good
    return {"value": _plain(dv.value), "type": type(dv.value).__name__, "status": status,
            "source_timestamp": dv.sourceTimestamp is not None}


def emulator(url: str) -> dict[str, Any]:  # pragma: no cover - a separate process
    import o6

    out: dict[str, Any] = {}
    with o6.Client(url) as client:
        furnace = client.objects.Furnace
        out["tcs"] = {tc: _data_value(client, child(furnace, tc)) for tc in ("TC1", "TC2", "TC3", "TC4")}
        t1h, t2h = child(furnace, "LampGroups/T1h"), child(furnace, "LampGroups/T2h")
        out["clamped"] = _name(client.write(t1h, o6.Double(1.7)))
        out["T1h_after"] = _plain(client.read(t1h))
        out["in_range"] = _name(client.write(t2h, o6.Double(0.25)))
        out["read_only"] = _name(client.write(furnace.TC1, o6.Double(1000.0)))
        out["lock_step"] = _plain(client.read(furnace.LockStep))
        out["watchdog_type"] = type(client.read(furnace.Watchdog)).__name__
        seen: list[float] = []
        client.monitor(furnace.TC1, lambda v: seen.append(float(v)), samplingInterval=0.0, queueSize=10)
        out["lamps_before"] = _plain(client.read(furnace.LampsEnabled))
        for k in range(1, 16):  # a client that feeds the watchdog for 1.5 s: the lamps go on
            client.write(furnace.Watchdog, o6.UInt32(k))
            time.sleep(0.1)
        out["lamps_fed"] = _plain(client.read(furnace.LampsEnabled))
        out["tc1_changes"] = len(seen)
        time.sleep(1.5)  # the watchdog still: the interlock trips within about a second
        out["lamps_after_silence"] = _plain(client.read(furnace.LampsEnabled))
        client.write(t1h, o6.Double(0.0))
        client.write(t2h, o6.Double(0.0))
    return out


def results(url: str, seconds: float) -> dict[str, Any]:  # pragma: no cover - a separate process
    import o6

    out: dict[str, Any] = {}
    with o6.Client(url) as client:
        current = child(client.objects, "Twin/Runs/Current")
        out["first"] = {name: _data_value(client, getattr(current, name)) for name in RESULTS}
        seen: list[Any] = []
        client.monitor(current.T, lambda v: seen.append(_plain(v)), samplingInterval=0.0, queueSize=50)
        time.sleep(seconds)
        out["t_updates"] = seen
        out["last"] = {name: _data_value(client, getattr(current, name)) for name in RESULTS}
        out["write"] = _name(client.write(current.T_mean_hat, o6.Double(0.0)))
    return out


def main() -> None:  # pragma: no cover - a separate process
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=("emulator", "results"))
    p.add_argument("url")
    p.add_argument("--seconds", type=float, default=2.0)
    args = p.parse_args()
    got = emulator(args.url) if args.what == "emulator" else results(args.url, args.seconds)
    print("RESULT " + json.dumps(got), flush=True)


if __name__ == "__main__":
    main()
