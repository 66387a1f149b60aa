"""OPC UA security on both sides: Basic256Sha256 Sign & Encrypt with certificates created on first use and
trusted only when copied into trusted/, user name and password, and the emulator refusing to serve
without security beyond loopback unless told to."""

from __future__ import annotations

import shutil
import stat
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from opcua_helpers import InProcessEmulator, child_env, endpoint, free_port

from twin.config import small_config
from twin.furnace.emulator.command import EmulateError, check_arguments
from twin.furnace.emulator.server import FurnaceEmulator
from twin.furnace.opcua.furnace import OpcUaFurnace
from twin.furnace.opcua.link import FurnaceUnavailable
from twin.furnace.opcua.nodes import NodeMap
from twin.furnace.opcua.options import OpcUaOptions
from twin.furnace.simulated import SimulatedFurnace

CFG = small_config()


@pytest.fixture(scope="module")
def secure_emulator(tmp_path_factory):
    folder = tmp_path_factory.mktemp("secure")
    port = free_port()
    emulator = FurnaceEmulator(SimulatedFurnace(CFG, radiation=None, tc_noise=0.0), endpoint(port),
                               NodeMap.default([g.name for g in CFG.lamps.groups]), eta_max=CFG.oscillation.eta_max,
                               T0=300.0, security="sign-encrypt", cert_dir=folder / "emulator" / "opcua",
                               users={"lab": "s3cret"})
    with InProcessEmulator(emulator):
        yield SimpleNamespace(port=port, folder=folder, emu_certs=folder / "emulator" / "opcua")


def twin(port: int, certs, **options) -> OpcUaFurnace:
    opts = OpcUaOptions(**{"security": "sign-encrypt", "username": "lab", "password": "s3cret",
                           "connect_timeout_s": 10.0, **options})
    return OpcUaFurnace(CFG, endpoint(port), options=opts, cert_dir=certs)


def test_sign_and_encrypt_with_certificates_trusted_both_ways(secure_emulator) -> None:
    e = secure_emulator
    certs = e.folder / "twin" / "opcua"
    # first use: this twin makes its certificate; the emulator does not know it yet.  One sentence that names
    # the certificate to trust and this twin's trust folder
    own_cert, own_key = certs / "twin-cert.der", certs / "twin-key.pem"
    with pytest.raises(FurnaceUnavailable) as refused:
        twin(e.port, certs)
    assert str(refused.value) == (
        f"{endpoint(e.port)} refused this twin's certificate {own_cert} (BadCertificateUntrusted): add it to the "
        f"trusted certificates of the furnace's OPC UA server (this twin trusts the furnace's certificate once it "
        f"is in {certs / 'trusted'})")
    assert own_cert.is_file() and stat.S_IMODE(own_key.stat().st_mode) == 0o600
    assert (e.emu_certs / "emulator-cert.der").is_file()
    shutil.copy(own_cert, e.emu_certs / "trusted" / "twin.der")  # the furnace trusts the twin ...
    with pytest.raises(FurnaceUnavailable, match="this twin does not trust the certificate of") as untrusted:
        twin(e.port, certs)  # ... but the twin does not trust the furnace yet: it keeps what it refused
    (saved,) = (certs / "rejected").glob("*.der")
    assert saved.read_bytes() == (e.emu_certs / "emulator-cert.der").read_bytes()
    assert f"saved as {saved}" in str(untrusted.value) and f"move it into {certs / 'trusted'}" in str(untrusted.value)
    shutil.copy(e.emu_certs / "emulator-cert.der", certs / "trusted" / "emulator.der")
    furnace = twin(e.port, certs)
    try:
        r = furnace.read(0.0)
        assert r.status == ("good",) * 4
        furnace.apply(np.zeros(6), 0.0)
        assert furnace.read(0.1).status == ("good",) * 4
    finally:
        furnace.close()
    with pytest.raises(FurnaceUnavailable, match="refused the user name or password"):
        twin(e.port, certs, password="wrong")
    with pytest.raises(FurnaceUnavailable, match="user name or password|does not offer"):
        twin(e.port, certs, username=None, password=None)  # anonymous: refused
    with pytest.raises(FurnaceUnavailable, match="does not offer security 'none'"):
        twin(e.port, certs, security="none")


def _args(**kw) -> SimpleNamespace:
    return SimpleNamespace(**{"endpoint": "opc.tcp://127.0.0.1:4840/furnace-twin/", "security": "none", "user": None,
                              "allow_insecure": False, **kw})


def test_serving_without_security_beyond_loopback_needs_the_flag(monkeypatch) -> None:
    assert check_arguments(_args())[0].startswith("opc.tcp://127.0.0.1")
    with pytest.raises(EmulateError, match="--allow-insecure"):
        check_arguments(_args(endpoint="opc.tcp://0.0.0.0:4840/furnace-twin/"))
    with pytest.raises(EmulateError, match="--allow-insecure"):
        check_arguments(_args(endpoint="opc.tcp://192.168.1.20:4840/"))
    assert check_arguments(_args(endpoint="opc.tcp://0.0.0.0:4840/", allow_insecure=True))
    assert check_arguments(_args(endpoint="opc.tcp://0.0.0.0:4840/", security="sign-encrypt"))
    monkeypatch.delenv("FURNACE_TWIN_OPCUA_PASSWORD", raising=False)
    with pytest.raises(EmulateError, match="FURNACE_TWIN_OPCUA_PASSWORD"):
        check_arguments(_args(user="lab"))
    monkeypatch.setenv("FURNACE_TWIN_OPCUA_PASSWORD", "pw")
    assert check_arguments(_args(user="lab"))[1] == {"lab": "pw"}


def test_the_emulate_command_refuses_with_a_message(tmp_path) -> None:
    out = subprocess.run([sys.executable, "-m", "furnace_twin.cli", "emulate", "--endpoint", "opc.tcp://0.0.0.0:4999/"],
                         capture_output=True, text=True, env=child_env(), cwd=tmp_path, timeout=120)
    assert out.returncode == 2 and "--allow-insecure" in out.stderr and "Traceback" not in out.stderr
    out = subprocess.run([sys.executable, "-m", "furnace_twin.cli", "emulate", "--endpoint", "http://127.0.0.1:4999/"],
                         capture_output=True, text=True, env=child_env(), cwd=tmp_path, timeout=120)
    assert out.returncode == 2 and "must start with opc.tcp://" in out.stderr
