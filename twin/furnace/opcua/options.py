"""How the twin connects to a furnace over OPC UA: environment ``FURNACE_TWIN_OPCUA_*`` (or explicit values).

The same settings serve ``furnace-twin serve`` (the dashboard's runs) and ``furnace-twin run``; the
scenario only names the endpoint, never credentials.

- ``FURNACE_TWIN_OPCUA_ENDPOINTS``: allow-list of endpoints (:mod:`twin.endpoints`), loopback
  by default;
- ``FURNACE_TWIN_OPCUA_SECURITY``: ``none`` or ``sign-encrypt`` (Basic256Sha256, Sign & Encrypt, certificates);
- ``FURNACE_TWIN_OPCUA_USERNAME``, ``FURNACE_TWIN_OPCUA_PASSWORD``: if the furnace asks for them;
- ``FURNACE_TWIN_OPCUA_MAPPING``: mapping file for a furnace whose node names differ
  (:mod:`twin.furnace.opcua.nodes`);
- ``FURNACE_TWIN_OPCUA_RECONNECT_S``: how long a lost link is retried before the run ends ``plant_lost``;
- ``FURNACE_TWIN_OPCUA_LATE_FRACTION``: a sample later than this fraction of t_s after it is due is missing.

Example
-------
>>> o = OpcUaOptions(security="sign-encrypt", reconnect_s=3.0)
>>> o.security, o.reconnect_s, str(o.allow_list()[0].network)
('sign-encrypt', 3.0, '127.0.0.1/32')
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from twin.endpoints import LOOPBACK_ALLOW_LIST, AllowEntry, parse_allow_list

Security = Literal["none", "sign-encrypt"]


class OpcUaOptions(BaseSettings):
    """The twin's side of an OPC UA link (client)."""

    model_config = SettingsConfigDict(env_prefix="FURNACE_TWIN_OPCUA_", frozen=True, extra="ignore")

    endpoints: str = Field(LOOPBACK_ALLOW_LIST, description="comma-separated hosts, host:port, networks or "
                           "opc.tcp:// URLs this server may connect to (loopback by default)")
    security: Security = Field("none", description="'sign-encrypt': Basic256Sha256 Sign & Encrypt with "
                               "certificates in <data dir>/opcua (created on first use)")
    username: str | None = Field(None, description="user name for the furnace's server, if it asks for one")
    password: SecretStr | None = Field(None, description="its password (environment only, never in a scenario)")
    mapping: Path | None = Field(None, description="mapping file for a furnace whose node names differ")
    reconnect_s: float = Field(10.0, ge=0.0, le=600.0, description="a lost link is retried this long (s)")
    late_fraction: float = Field(0.5, gt=0.0, le=5.0, description="a sample later than this x t_s is missing")
    connect_timeout_s: float = Field(5.0, gt=0.0, le=120.0, description="connecting and each request (s)")

    @field_validator("endpoints")
    @classmethod
    def _endpoints(cls, v: str) -> str:
        parse_allow_list(v)  # raises ValueError naming the bad entry
        return v

    def allow_list(self) -> tuple[AllowEntry, ...]:
        return parse_allow_list(self.endpoints)

    def secret(self) -> str | None:
        return None if self.password is None else self.password.get_secret_value()


def certificate_dir(data_dir: str | Path) -> Path:
    """Where a data directory keeps OPC UA certificates: own ones, and ``trusted/`` peers."""
    return Path(data_dir) / "opcua"
