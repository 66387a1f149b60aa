"""What configures an OPC UA link: the address space and mapping files, the endpoint allow-list, the
scenario's plant and the interlock's pure logic (no network here)."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from twin.endpoints import endpoint_allowed, is_loopback, parse_allow_list, parse_endpoint
from twin.furnace.emulator.interlock import WatchdogInterlock, clamp_setpoint
from twin.furnace.emulator.timing import TimingRecord
from twin.furnace.opcua.nodes import MappingError, NodeMap, load_mapping, mapping_from_dict
from twin.scenario import Scenario

GROUPS = ("T1h", "T2h", "T3h", "T4h", "T1v", "T2v")


def test_default_address_space_is_product_md() -> None:
    m = NodeMap.default(GROUPS)
    assert m.object_path == ("Furnace",)
    assert {n: s.path for n, s in m.nodes.items() if n.startswith("TC")} == {f"TC{i}": (f"TC{i}",) for i in range(1, 5)}
    assert all(m.nodes[g].path == ("LampGroups", g) for g in GROUPS)
    for name in ("Eta", "OscillationEnabled", "Amplitude", "Period", "Watchdog", "LampsEnabled"):
        assert m.nodes[name].path == (name,)


def test_mapping_file_paths_node_ids_units(tmp_path) -> None:
    f = tmp_path / "lab.toml"
    f.write_text('object = "Plant/Annealer"\nnamespace = "urn:lab"\n[nodes]\nTC1 = "Sensors/TE101"\n'
                 'TC2 = {node = "ns=3;s=TE102", offset = -273.15}\nT1h = {node = "Heating/Z1", scale = 100.0}\n')
    m = load_mapping(f, GROUPS)
    assert m.object_path == ("Plant", "Annealer") and m.namespace == "urn:lab" and m.source == str(f)
    assert m.nodes["TC1"].path == ("Sensors", "TE101")
    assert m.nodes["TC2"].node_id == "ns=3;s=TE102" and m.nodes["TC2"].to_twin(826.85) == pytest.approx(1100.0)
    assert m.nodes["T1h"].to_furnace(0.5) == 50.0
    assert m.nodes["TC3"].path == ("TC3",) and m.nodes["T2h"].path == ("LampGroups", "T2h")  # the rest: defaults


@pytest.mark.parametrize(("data", "says"), [
    ({"nodes": {"TC5": "x"}}, "unknown names ['TC5']"),
    ({"nodes": {"Watchdog": {"node": "W", "scale": 2.0}}}, "takes no scale"),
    ({"nodes": {"TC1": {"node": "A", "scale": 0.0}}}, "non-zero"),
    ({"nodes": {"TC1": {"node": "A", "gain": 2.0}}}, "unknown keys ['gain']"),
    ({"nodes": {"TC1": "A//B"}}, "not a browse path"),
    ({"objekt": "Furnace"}, "unknown keys ['objekt']"),
    ({"nodes": {"TC1": 3}}, "expected a browse path"),
])
def test_mapping_errors_name_the_entry(data, says) -> None:
    with pytest.raises(MappingError, match=says.replace("[", r"\[").replace("]", r"\]")):
        mapping_from_dict(data, GROUPS, source="lab.toml")


def test_mapping_file_unreadable_or_not_toml(tmp_path) -> None:
    with pytest.raises(MappingError, match="cannot read"):
        load_mapping(tmp_path / "missing.toml", GROUPS)
    bad = tmp_path / "bad.toml"
    bad.write_text("nodes = [")
    with pytest.raises(MappingError, match="not valid TOML"):
        load_mapping(bad, GROUPS)


def test_allow_list_default_is_loopback() -> None:
    loopback = parse_allow_list("127.0.0.1,::1,localhost")
    for ok in ("opc.tcp://127.0.0.1:4840/x/", "opc.tcp://localhost:4840", "opc.tcp://[::1]:4841/"):
        assert endpoint_allowed(ok, loopback), ok
    for refused in ("opc.tcp://10.0.0.5:4840/", "opc.tcp://127.0.0.2:4840/", "opc.tcp://furnace.lab:4840/",
                    "opc.tcp://localhost.evil.example:4840/"):
        assert not endpoint_allowed(refused, loopback), refused


def test_allow_list_networks_hosts_ports() -> None:
    allowed = parse_allow_list("10.0.0.0/24:4840, plc.lab, opc.tcp://192.168.1.7:4850, [fd00::1]:4840")
    assert endpoint_allowed("opc.tcp://10.0.0.200:4840/", allowed)
    assert not endpoint_allowed("opc.tcp://10.0.1.1:4840/", allowed)
    assert not endpoint_allowed("opc.tcp://10.0.0.9:4841/", allowed)  # the entry names a port
    assert endpoint_allowed("opc.tcp://PLC.lab:4999/", allowed)  # host names compare case-insensitively
    assert endpoint_allowed("opc.tcp://192.168.1.7:4850/furnace/", allowed)
    assert not endpoint_allowed("opc.tcp://192.168.1.7:4840/", allowed)
    assert endpoint_allowed("opc.tcp://[fd00::1]:4840/", allowed)
    assert parse_endpoint("opc.tcp://plc.lab/").port == 4840  # the OPC UA default port
    with pytest.raises(ValueError, match="not a host, address or network"):
        parse_allow_list("10.0.0.0/33")
    with pytest.raises(ValueError, match="no credentials"):
        parse_endpoint("opc.tcp://user:pw@127.0.0.1:4840/")
    assert is_loopback("127.0.0.5") and is_loopback("localhost") and not is_loopback("0.0.0.0")


def test_scenario_plant_runs_in_real_time() -> None:
    s = Scenario.model_validate({"plant": {"kind": "opcua", "endpoint": "opc.tcp://127.0.0.1:4840/furnace-twin/"}})
    assert s.speed == 1.0 and s.plant.kind == "opcua"  # real time by default
    assert Scenario().plant.kind == "simulated"
    with pytest.raises(ValidationError, match="speed must be 1"):
        Scenario.model_validate({"plant": {"kind": "opcua"}, "speed": 5.0})
    with pytest.raises(ValidationError, match="speed must be 1"):
        Scenario.model_validate({"plant": {"kind": "opcua"}, "speed": "max"})
    with pytest.raises(ValidationError, match="opc.tcp://"):
        Scenario.model_validate({"plant": {"kind": "opcua", "endpoint": "http://127.0.0.1/"}})


def test_interlock_trips_after_a_still_watchdog_and_rearms() -> None:
    w = WatchdogInterlock(timeout_s=1.0)
    assert not w.lamps_enabled  # no client yet: lamps off
    for k in range(20):  # a client writing every 0.1 s keeps the lamps on
        w.feed(k, now=0.1 * k)
        assert not w.check(now=0.1 * k + 0.05) and w.lamps_enabled
    assert not w.check(now=1.9 + 0.99)
    assert w.check(now=1.9 + 1.01) and not w.lamps_enabled and w.trips == 1
    assert not w.check(now=5.0) and w.trips == 1  # a trip is counted once
    w.feed(19, now=6.0)
    assert not w.lamps_enabled  # the same value again is no sign of life
    w.feed(20, now=6.1)
    assert w.lamps_enabled


def test_setpoints_clamp_to_the_thyristor_range() -> None:
    assert [clamp_setpoint(u) for u in (-1.0, 0.0, 0.42, 1.0, 7.0, float("inf"), float("nan"))] == \
        [0.0, 0.0, 0.42, 1.0, 1.0, 0.0, 0.0]


def test_timing_record_latency_and_periods() -> None:
    rec = TimingRecord()
    for k in range(100):
        rec.reading(10.0 + 0.1 * k + (0.002 if k % 2 else 0.0))  # the emulator's ticks jitter by 2 ms
        if k not in (40, 41):  # the client misses two samples
            rec.write(10.0 + 0.1 * k + 0.005 + 0.001 * (k % 3))
    s = rec.summary()
    assert s["unanswered_readings"] == 2 and s["tc_to_lamp_ms"]["n"] == 98
    assert s["tc_to_lamp_ms"]["max"] == pytest.approx(7.0, abs=1e-6)
    assert s["emulator_period_ms"]["p50"] == pytest.approx(100.0, abs=2.001)
    assert s["twin_period_ms"]["max"] == pytest.approx(300.0, abs=3.0)  # the gap of the missed samples
