"""A third-party furnace on an independent OPC UA stack (o6, open62541): its own namespace, string NodeIds, PLC
types and units, a crude lumped thermal model, a watchdog interlock.  What an integrator meets at a real furnace,
and not the twin's emulator: the twin drives it through a mapping file (tests/furnace/test_o6_interop.py).

Run as a script (never imported by the test process: o6 ends its process ten minutes after ``import o6``)::

    python furnace.py --port 4850 --state state.json [--spare-namespaces 2]

Address space (namespace ``urn:lab:annealer``, at an index that ``--spare-namespaces`` shifts, as a server
restarted with another configuration would): ``Objects/Plant/Annealer`` holding ``ns=<i>;s=PLC1.TE101`` ..
``PLC1.TE104`` (Float, deg C, read-only, a source timestamp per 0.1 s sample), ``PLC1.Zone1`` .. ``PLC1.Zone6``
(Float, percent, written values clamped to 0..100 with ``GoodClamped``), ``PLC1.Heartbeat`` (UInt16: the twin's
watchdog, it wraps), ``PLC1.LampsOn`` (Boolean, read-only: false once the heartbeat has been still for 1 s),
``PLC1.Drive.On`` (Boolean), ``PLC1.Drive.Stroke`` and ``PLC1.Drive.Pos`` (Double, mm), ``PLC1.Drive.Cycle``
(Double, s).

The model (one plate temperature T, K): dT/dt = R u_mean - B (T^4 - T_a^4), with R = 55 K/s (the small
furnace's heating rate at full power near 400 K) and B = 2.37e-11 K^-3 s^-1 (its hold at 700 K needs about 10 %
power); TC_i = T + d_i (T - T_a) / 400 K with d = (-3, 2, 1, 0) K.  ``--state`` keeps T and the wall time of
each sample, so a restarted server goes on from where the furnace is (it cooled meanwhile, lamps off).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import threading
import time

T_AMBIENT = 300.0  # K
RATE = 55.0  # K/s at full power
LOSS = 2.37e-11  # K^-3 s^-1
T_S = 0.1  # s between samples
WATCHDOG_S = 1.0
TC_SPREAD = (-3.0, 2.0, 1.0, 0.0)  # K per 400 K above ambient
ZONES = 6


def advance(T: float, u_mean: float, dt: float) -> float:
    """The lumped model over dt (explicit Euler in steps of at most 10 ms)."""
    n = max(1, math.ceil(dt / 0.01))
    h = dt / n
    for _ in range(n):
        T += h * (RATE * u_mean - LOSS * (T**4 - T_AMBIENT**4))
    return T


def main() -> None:  # pragma: no cover - a separate process
    p = argparse.ArgumentParser()
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--state", required=True)
    p.add_argument("--spare-namespaces", type=int, default=0)
    p.add_argument("--seconds", type=float, default=300.0, help="stop after this long (o6 allows ten minutes)")
    args = p.parse_args()

    import lab_namespace
    import o6
    import spare_namespaces

    T, last = T_AMBIENT, time.time()
    if os.path.exists(args.state):  # the furnace went on while its server was down: lamps off
        saved = json.loads(open(args.state).read())
        T = advance(float(saved["T"]), 0.0, max(time.time() - float(saved["wall"]), 0.0))
    server = o6.Server(port=args.port)
    if args.spare_namespaces:
        server.ns.append(spare_namespaces)
    server.ns.append(lab_namespace)
    uris = list(server.read("i=2255"))
    idx = uris.index("urn:lab:annealer")

    def nid(name: str) -> str:
        return f"ns={idx};s=PLC1.{name}"

    plant = server.addObject("Plant", server.objectsNode, nodeId=f"ns={idx};s=Plant", ns=idx)
    annealer = server.addObject("Annealer", plant, nodeId=f"ns={idx};s=Plant.Annealer", ns=idx)
    tcs = [server.addVariable(f"TE10{i + 1}", annealer, o6.Float(T - 273.15), nodeId=nid(f"TE10{i + 1}"),
                              writable=False, ns=idx) for i in range(4)]
    lamps_on = server.addVariable("LampsOn", annealer, o6.Boolean(False), nodeId=nid("LampsOn"), writable=False,
                                  ns=idx)
    drive = server.addObject("Drive", annealer, nodeId=nid("Drive"), ns=idx)
    server.addVariable("On", drive, o6.Boolean(False), nodeId=nid("Drive.On"), ns=idx)
    server.addVariable("Stroke", drive, o6.Double(48.0), nodeId=nid("Drive.Stroke"), ns=idx)
    server.addVariable("Cycle", drive, o6.Double(18.0), nodeId=nid("Drive.Cycle"), ns=idx)
    server.addVariable("Pos", drive, o6.Double(0.0), nodeId=nid("Drive.Pos"), writable=False, ns=idx)
    lock = threading.Lock()
    zones = [0.0] * ZONES
    beat = {"value": None, "at": -math.inf, "writes": 0}

    def zone_callbacks(k: int):
        def read(node, *, range, session, includeSourceTimestamp):
            with lock:
                return (o6.StatusCode.GOOD, o6.Float(zones[k]))

        def write(node, value, *, range, session):
            v = float(value.value)
            clamped = min(max(v, 0.0), 100.0) if math.isfinite(v) else 0.0
            with lock:
                zones[k] = clamped
            return (o6.StatusCode.GOOD_CLAMPED if clamped != v else o6.StatusCode.GOOD,)

        return read, write

    for k in range(ZONES):
        zone = server.addVariable(f"Zone{k + 1}", annealer, o6.Float(0.0), nodeId=nid(f"Zone{k + 1}"), ns=idx)
        read, write = zone_callbacks(k)
        server.implement(zone, read=read, write=write)

    def beat_read(node, *, range, session, includeSourceTimestamp):
        with lock:
            return (o6.StatusCode.GOOD, o6.UInt16(beat["value"] or 0))

    def beat_write(node, value, *, range, session):
        if value.status is not None and o6.StatusCode.BAD in value.status:
            return (o6.StatusCode.GOOD,)  # no sign of life
        v = int(value.value)
        with lock:
            if v != beat["value"]:
                beat["value"], beat["at"] = v, time.monotonic()
                beat["writes"] += 1
        return (o6.StatusCode.GOOD,)

    heartbeat = server.addVariable("Heartbeat", annealer, o6.UInt16(0), nodeId=nid("Heartbeat"), ns=idx)
    server.implement(heartbeat, read=beat_read, write=beat_write)
    server.start()
    print("READY " + json.dumps({"namespace_index": idx, "namespaces": uris, "T": T}), flush=True)

    start, k = time.monotonic(), 0
    while time.monotonic() - start < args.seconds:
        k += 1
        time.sleep(max(start + k * T_S - time.monotonic(), 0.0))
        with lock:
            enabled = time.monotonic() - beat["at"] <= WATCHDOG_S
            u = sum(zones) / (100.0 * ZONES) if enabled else 0.0
        now = time.time()
        T = advance(T, u, now - last)
        last = now
        stamp = o6.DateTime(datetime.datetime.fromtimestamp(now, datetime.UTC))
        for tc, d in zip(tcs, TC_SPREAD, strict=True):
            server.write(tc, o6.DataValue(value=o6.Float(T + d * (T - T_AMBIENT) / 400.0 - 273.15),
                                          sourceTimestamp=stamp))
        server.write(lamps_on, o6.DataValue(value=o6.Boolean(enabled), sourceTimestamp=stamp))
        tmp = args.state + ".tmp"
        with open(tmp, "w") as fh:
            fh.write(json.dumps({"T": T, "wall": now, "writes": beat["writes"]}))
        os.replace(tmp, args.state)
    server.stop()


if __name__ == "__main__":
    main()
