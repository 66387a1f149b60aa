"""The emulator and the plant adapter over loopback OPC UA (emulator in this process, on its own thread):
product.md's address space, clamps and the watchdog interlock as a client sees them, TC statuses and
source timestamps through OpcUaFurnace, a late sample, a reconnection, a mapping file on both sides."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest
from opcua_helpers import InProcessEmulator, Peek, TcpProxy, endpoint, free_port

from twin.config import small_config
from twin.furnace.emulator.server import FurnaceEmulator
from twin.furnace.interface import FurnaceLost, Readings
from twin.furnace.opcua.furnace import OpcUaFurnace
from twin.furnace.opcua.link import FurnaceUnavailable
from twin.furnace.opcua.nodes import NodeMap, load_mapping
from twin.furnace.opcua.options import OpcUaOptions
from twin.furnace.simulated import SimulatedFurnace

#: its tests run in real time (sleeps, a watchdog, late ticks): scripts/test.sh runs them after the parallel part,
#: alone on the machine (a full parallel run on a slow day left 12 of 30 samples in time, against >= 20)
pytestmark = pytest.mark.realtime

CFG = small_config()
GROUPS = [g.name for g in CFG.lamps.groups]


class Faulty:
    """A simulated furnace whose TC2 reports a sensor fault and whose TC3 reading is lost in [t_a, t_b), and
    which can stall (its readings take ``stall_s`` longer, like an overloaded controller)."""

    def __init__(self, inner: SimulatedFurnace, t_a: float = 1e9, t_b: float = 1e9) -> None:
        self.inner, self.t_a, self.t_b = inner, t_a, t_b
        self.stall_s = 0.0
        self.kind, self.realtime = "test", False
        self.t_s, self.tc_positions = inner.t_s, inner.tc_positions

    def read(self, t: float) -> Readings:
        r = self.inner.read(t)
        if self.stall_s:
            time.sleep(self.stall_s)
        if not self.t_a <= t < self.t_b:
            return r
        values = r.values.copy()
        values[1:3] = np.nan
        return Readings(values, r.timestamps, ("good", "bad", "missing", "good"))

    def apply(self, u, t):
        self.inner.apply(u, t)

    def motion(self, t):
        return self.inner.motion(t)

    def set_oscillation(self, spec, t):
        self.inner.set_oscillation(spec, t)

    def true_field(self):
        return self.inner.true_field()

    def drain_events(self):
        return ()

    def close(self) -> None:
        self.inner.close()


def make_emulator(furnace, port: int, node_map: NodeMap | None = None, **kw) -> FurnaceEmulator:
    return FurnaceEmulator(furnace, endpoint(port), node_map or NodeMap.default(GROUPS),
                           eta_max=CFG.oscillation.eta_max, T0=CFG.specimen.initial_temperature, **kw)


def connect(port: int, tmp_path, **options) -> OpcUaFurnace:
    opts = OpcUaOptions(**{"reconnect_s": 3.0, "connect_timeout_s": 3.0, **options})
    return OpcUaFurnace(CFG, endpoint(port), options=opts, cert_dir=tmp_path / "twin-opcua")


@pytest.fixture(scope="module")
def shared_emulator():
    """One emulator for the tests below (an OPC UA server takes seconds to start on a loaded machine)."""
    port = free_port()
    furnace = Faulty(SimulatedFurnace(CFG, radiation=None, tc_noise=0.0))
    with InProcessEmulator(make_emulator(furnace, port)) as emu:
        yield emu, furnace, port


def _on_schedule(emu) -> None:
    """Wait until the shared emulator has gone on by 0.5 s of its time: a test before may have stalled it."""
    t_emu = emu.emulator.t
    end = time.monotonic() + 30.0
    while emu.emulator.t - t_emu < 0.5 and time.monotonic() < end:
        time.sleep(0.05)


@pytest.fixture
def emulated(shared_emulator):
    emu, furnace, port = shared_emulator
    furnace.t_a = furnace.t_b = 1e9
    furnace.stall_s = 0.0
    _on_schedule(emu)
    yield shared_emulator


def test_address_space_clamps_and_watchdog_as_a_client_sees_them(emulated) -> None:
    emu, _, port = emulated
    peek = Peek(endpoint(port))
    try:
        from asyncua import ua

        for tc in ("TC1", "TC2", "TC3", "TC4"):
            dv = peek.data_value(tc)
            assert dv.Value.VariantType == ua.VariantType.Double and dv.SourceTimestamp is not None
        assert peek.nodes["Watchdog"].read_data_type_as_variant_type() == ua.VariantType.UInt32
        assert set(GROUPS) <= set(peek.nodes)
        for node in ("TC1", "Eta", "LampsEnabled", "LockStep"):  # read-only for clients, and told so
            with pytest.raises(ua.uaerrors.BadNotWritable):
                peek.nodes[node].write_value(ua.Variant(1.0 if node not in ("LampsEnabled", "LockStep") else True))
        assert peek.value("LockStep") is False  # this emulator keeps real time
        peek.nodes["T1h"].write_value(ua.Variant(1.7, ua.VariantType.Double))
        peek.nodes["T2h"].write_value(ua.Variant(-0.3, ua.VariantType.Double))
        peek.nodes["T3h"].write_value(ua.Variant(0.42, ua.VariantType.Double))
        assert (peek.value("T1h"), peek.value("T2h"), peek.value("T3h")) == (1.0, 0.0, 0.42)
        peek.nodes["Amplitude"].write_value(ua.Variant(0.9, ua.VariantType.Double))
        assert peek.value("Amplitude") == pytest.approx(CFG.oscillation.eta_max)  # the drive's limit
        # no client has written the watchdog: lamps off; a value written with a Bad status is no sign of life
        assert peek.value("LampsEnabled") is False
        peek.nodes["Watchdog"].write_attribute(ua.AttributeIds.Value, ua.DataValue(
            ua.Variant(7, ua.VariantType.UInt32), StatusCode=ua.StatusCode(ua.UInt32(ua.StatusCodes.BadSensorFailure))))
        time.sleep(0.3)
        assert peek.value("LampsEnabled") is False and emu.emulator.interlock.value is None
        # a new value turns them on; 1 s of silence trips
        t_fed = time.monotonic()
        peek.nodes["Watchdog"].write_value(ua.Variant(1, ua.VariantType.UInt32))
        time.sleep(0.3)
        assert peek.value("LampsEnabled") is True
        while peek.value("LampsEnabled") and time.monotonic() - t_fed < 5:
            time.sleep(0.02)
        tripped_after = time.monotonic() - t_fed
        assert 1.0 <= tripped_after < 3.0 and emu.emulator.interlock.trips == 1
        peek.nodes["Watchdog"].write_value(ua.Variant(2, ua.VariantType.UInt32))
        time.sleep(0.3)
        assert peek.value("LampsEnabled") is True
    finally:
        peek.close()


def test_readings_statuses_timestamps_and_the_lamps(emulated, tmp_path) -> None:
    emu, furnace, port = emulated
    twin = connect(port, tmp_path)
    try:
        r0 = twin.read(0.0)
        assert r0.status == ("good",) * 4 and np.allclose(r0.timestamps, 0.0)
        assert twin.true_field() is None and twin.realtime
        t_plant0 = emu.emulator.t
        furnace.t_a, furnace.t_b = t_plant0 + 0.45, t_plant0 + 0.95  # TC2 faulty, TC3 lost for 5 samples
        readings = []
        for j in range(1, 61):  # 15 samples, and more until 6 are complete (a CI run under load had 5 of 15)
            twin.apply(np.full(6, 1.0), (j - 1) * CFG.sampling.t_s)
            readings.append(twin.read(j * CFG.sampling.t_s))
            if j >= 15 and sum(r.status == ("good",) * 4 for r in readings) >= 6:
                break
        faulty = [r for r in readings if r.status[1] == "bad"]
        assert 2 <= len(faulty) <= 6, [r.status for r in readings]
        for r in faulty:  # a sensor fault is Bad (value not usable), a lost reading is missing
            assert r.status[2] == "missing" and np.isnan(r.values[1:3]).all()
        good = [r for r in readings if r.status == ("good",) * 4]
        assert len(good) >= 6, [r.status for r in readings]  # (on a loaded machine a few may come late)
        for j, r in enumerate(readings, start=1):  # each reading's source timestamp lies in its sample
            stamped = r.timestamps[np.isfinite(r.timestamps)]
            assert np.all(np.abs(stamped - j * CFG.sampling.t_s) <= 0.5 * CFG.sampling.t_s + 1e-9), (j, r.timestamps)
        assert readings[-1].values[0] > r0.values[0] + 1.0  # the lamps heat: the writes reached the plant
        assert emu.emulator.interlock.lamps_enabled
    finally:
        twin.close()
    time.sleep(0.3)
    assert all(emu.emulator.space.value(g) == 0.0 for g in GROUPS)  # close() commanded the lamps off


def test_a_late_sample_is_missing_and_the_next_one_counts(emulated, tmp_path) -> None:
    """A furnace that publishes more than half a period late: its samples are missing (the loop goes on at
    their deadlines), what comes afterwards is dropped, not filed under a later sample."""
    _, furnace, port = emulated
    twin = connect(port, tmp_path)
    try:
        twin.read(0.0)
        t = CFG.sampling.t_s

        def statuses(js: range) -> list[tuple[str, ...]]:
            out = []
            for j in js:
                twin.apply(np.zeros(6), (j - 1) * t)
                out.append(twin.read(j * t).status)
            return out

        on_time = statuses(range(1, 11))
        assert sum(st == ("good",) * 4 for st in on_time) >= 6, on_time  # (a loaded machine may be late too)
        dropped_before = twin.late_readings
        furnace.stall_s = 0.12  # from now on the furnace publishes 120 ms after its samples are due
        stalled = statuses(range(11, 19))
        assert sum(st == ("missing",) * 4 for st in stalled) >= 3, stalled
        assert twin.late_readings > dropped_before  # what came after its deadline was dropped
    finally:
        furnace.stall_s = 0.0
        twin.close()


class Clocked(Faulty):
    """A furnace whose every reading is its own time (1000 K + t): a reading filed under another sample shows."""

    def read(self, t: float) -> Readings:
        r = self.inner.read(t)
        return Readings(np.full(4, 1000.0 + t), r.timestamps, r.status)


def test_a_tick_that_runs_late_is_filed_under_its_own_sample(tmp_path) -> None:
    """The emulator's event loop held up just before some ticks (a loaded machine), so that they run late: each
    sample is stamped with its own time and filed under it (stamped with the time the tick ran, a sample more
    than half a period late went under the next one).  A tick later than a whole period skips a sample (the
    furnace lost it): missing, never misfiled."""
    port = free_port()
    with InProcessEmulator(make_emulator(Clocked(SimulatedFurnace(CFG, radiation=None, tc_noise=0.0)), port)) as emu:
        twin = connect(port, tmp_path, late_fraction=3.0)  # samples may come 0.3 s late
        t = CFG.sampling.t_s
        got = []
        try:
            twin.read(0.0)
            origin = None
            for j in range(1, 31):
                twin.apply(np.zeros(6), (j - 1) * t)
                r = twin.read(j * t)
                if r.status[0] == "good":
                    origin = r.values[0] - 1000.0 - j * t if origin is None else origin
                    got.append((j, round(r.values[0] - 1000.0 - origin - j * t, 6)))
                if j % 3 == 0:  # 40 ms after sample j came, hold the emulator's loop 120 ms: tick j + 1 runs late
                    time.sleep(0.04)
                    emu.loop.call_soon_threadsafe(time.sleep, 0.12)
        finally:
            twin.close()
    assert len(got) >= 20, got
    assert [j for j, off in got if off != 0.0] == [], got  # each reading is of its own sample


def test_reconnection_within_the_window_and_loss_after_it(emulated, tmp_path) -> None:
    """A network blip (the relay drops the connection and turns the twin away for 1 s) is bridged; a link
    that stays down for longer than reconnect_s is lost for good (FurnaceLost from read)."""
    _, _, port = emulated
    proxy = TcpProxy(port)
    twin = OpcUaFurnace(CFG, endpoint(proxy.port), options=OpcUaOptions(reconnect_s=8.0, connect_timeout_s=5.0),
                        cert_dir=tmp_path / "twin-opcua")
    try:
        twin.read(0.0)
        u = np.full(6, 0.7)
        twin.apply(u, 0.0)
        assert twin.delivered(u, 0.0).tolist() == u.tolist()
        proxy.refuse = True
        proxy.cut()
        time.sleep(0.3)
        assert twin.delivered(u, 0.0).tolist() == u.tolist()  # the furnace holds the last command ...
        time.sleep(0.9)
        assert twin.delivered(u, 0.0).tolist() == [0.0] * 6  # ... until its watchdog has had a second
        proxy.refuse = False
        end = time.monotonic() + 10
        while twin._link.state != "connected" and time.monotonic() < end:
            time.sleep(0.05)
        events = twin.drain_events()
        assert twin._link.state == "connected", events
        assert any("lost" in e for e in events) and any("restored after" in e for e in events)
        twin.read(0.0)  # readings flow again (a fresh anchor gets a fresh sample)
        t_gone = time.monotonic()  # before the cut: the link may notice it (and start its window) at once
        proxy.close()
        statuses = []
        with pytest.raises(FurnaceLost, match="not restored within 8 s"):
            for j in range(1, 500):
                statuses.append(twin.read(j * CFG.sampling.t_s).status)  # no readings meanwhile, then the loss
        assert 8.0 <= time.monotonic() - t_gone < 14.0
        # while the link is down the readings are the link's loss ("unlinked"), which the fault detection does
        # not count against the TCs; only the samples before the client noticed the cut are "missing"
        assert statuses and statuses[-1] == ("unlinked",) * 4, statuses[-5:]
        assert sum(st == ("unlinked",) * 4 for st in statuses) >= 0.8 * len(statuses), statuses
    finally:
        twin.close()
        proxy.close()


def test_a_silent_furnace_is_given_up_and_its_lamps_commanded_off(emulated, tmp_path) -> None:
    """The link stays up but no readings come (the furnace's controller hangs): after reconnect_s the run
    gives the furnace up, and closing it still writes the lamps off over the live link."""
    emu, furnace, port = emulated
    twin = connect(port, tmp_path, reconnect_s=1.0)
    try:
        twin.read(0.0)
        t = CFG.sampling.t_s
        for j in range(1, 4):
            twin.apply(np.full(6, 0.8), (j - 1) * t)
            twin.read(j * t)
        time.sleep(0.3)
        assert emu.emulator.space.value("T2h") == pytest.approx(0.8)
        furnace.stall_s = 2.5  # the next readings come 2.5 s late
        with pytest.raises(FurnaceLost, match="no readings from the furnace"):
            for j in range(4, 100):
                twin.apply(np.full(6, 0.8), (j - 1) * t)
                twin.read(j * t)
        assert twin._link.state == "connected"  # given up, but the link is still there ...
    finally:
        twin.close()
        furnace.stall_s = 0.0
    assert all(emu.emulator.space.value(g) == 0.0 for g in GROUPS)  # ... so the lamps went off


def test_a_stalled_twin_learns_what_the_furnace_did_meanwhile(emulated, tmp_path) -> None:
    """The twin's loop stalls 1.3 s after reading a sample (a loaded machine, a long pause): its samples wait in
    the buffer and are taken complete, so none is late, but its command went out late and the furnace's watchdog
    switched the lamps off for the last 0.3 s.  A CI run that did this ended 0.29 % of the setpoint off the
    in-process run and said nothing; the run's events now say both."""
    emu, _, port = emulated  # (on its schedule again: the fixture waits)
    twin = connect(port, tmp_path)
    trips = emu.emulator.interlock.trips
    events: list[str] = []
    try:
        t = CFG.sampling.t_s
        twin.read(0.0)
        for j in range(0, 40):
            if j:
                twin.read(j * t)
            if j == 10:
                time.sleep(1.3)  # between reading sample 10 and answering it
            twin.apply(np.full(6, 0.5), j * t)
            events += twin.drain_events()
        time.sleep(0.2)
        events += twin.drain_events()
    finally:
        twin.close()
    assert emu.emulator.interlock.trips == trips + 1
    # the stall's lateness, named where the twin caught up: the longest of its run of late samples.  A loaded
    # machine may add true events of its own, each well under the stall: one before the stall ("fell behind ...
    # at t = 0.4 s: the sample was taken 0.07 s after it was due"), or one that opened the run the stall joined (a
    # CI run: "fell behind ... at t = 0.8 s: its lamp command went out 0.12 s ...", and no event at t = 1.0 s).
    caught = [re.search(r"the longest (\d+\.\d+) s at t = (\d+\.\d) s", e) for e in events
              if e.startswith("the twin caught up with the furnace")]
    stall = [m for m in caught if m and m.group(2) == "1.0"]
    assert len(stall) == 1, events
    late_s = float(stall[0].group(1))
    assert 1.1 <= late_s <= 1.5, events  # 1.3 s of stall, less what was left of the period
    behind = [e for e in events if "fell behind" in e]
    assert behind and float(re.search(r"at t = (\d+\.\d) s", behind[0]).group(1)) <= 1.0, events
    others = [e for e in behind if "at t = 1.0 s" not in e]
    assert all(float(re.search(r"(\d+\.\d+) s after", e).group(1)) < 0.5 for e in others), others
    off = [e for e in events if "switched its lamps off" in e]
    assert off and any("enabled its lamps again" in e for e in events), events
    t_off = float(off[0].split("t = ")[1].split(" s")[0])
    assert 1.9 <= t_off <= 2.4, off  # 1 s of silence after the command for sample 9 (t = 0.9 s), within a tick
    assert twin.overdue_samples >= 2


MAPPING = """object = "Plant/Annealer"
[nodes]
TC1 = {node = "Sensors/TE101", offset = -273.15}
TC2 = {node = "ns=3;s=TE102", offset = -273.15}
TC3 = {node = "nsu=urn:lab:annealer;s=PLC1.TE103", offset = -273.15}
T1h = {node = "Heating/Zone1", scale = 100.0}
Watchdog = "Safety/Heartbeat"
"""


def test_a_furnace_with_other_node_names_through_a_mapping_file(tmp_path) -> None:
    from asyncua import ua

    mapping = tmp_path / "lab.toml"
    mapping.write_text(MAPPING)
    port = free_port()
    node_map = load_mapping(mapping, GROUPS)
    inner = SimulatedFurnace(CFG, radiation=None, tc_noise=0.0)
    with InProcessEmulator(make_emulator(inner, port, node_map)) as emu:
        with pytest.raises(FurnaceUnavailable, match="has no object Furnace under Objects"):
            connect(port, tmp_path)  # the default address space is not there
        twin = connect(port, tmp_path, mapping=mapping)
        try:
            r = twin.read(0.0)
            assert r.status == ("good",) * 4
            # the wire carries deg C (about 27 for a cold plate); the twin reads kelvin again
            assert np.all((r.values > 290.0) & (r.values < 400.0)), r.values
            for j in range(1, 4):
                twin.apply(np.array([0.5, 0, 0, 0, 0, 0]), (j - 1) * CFG.sampling.t_s)
                twin.read(j * CFG.sampling.t_s)
            time.sleep(0.2)
            space = emu.emulator.space
            raw = space.server.read_attribute_value(space.nodes["T1h"].nodeid).Value.Value
            assert raw == pytest.approx(50.0) and space.value("T1h") == pytest.approx(0.5)  # percent on the wire
            assert emu.emulator.interlock.lamps_enabled  # the watchdog under its own name
            # the nsu= node is served in its own namespace, and the twin found it there, not in namespace 0
            te103 = space.nodes["TC3"].nodeid
            uris = space.server.read_attribute_value(ua.NodeId(ua.ObjectIds.Server_NamespaceArray))
            assert te103.NamespaceIndex > 0 and uris.Value.Value[te103.NamespaceIndex] == "urn:lab:annealer"
            assert twin._link.nodes["TC3"].node.nodeid == te103
        finally:
            twin.close()
