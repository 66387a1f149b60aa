"""Server settings of the live dashboard (pydantic-settings, env prefix ``FURNACE_TWIN_``).

Every field can be set from the environment, e.g. ``FURNACE_TWIN_API_TOKEN=secret`` or
``FURNACE_TWIN_MAX_CONCURRENT_RUNS=3``; ``furnace-twin serve`` passes host, ports and the
data directory explicitly.  The defaults bind to loopback only.  Runs on a furnace over OPC UA take
their link settings from ``FURNACE_TWIN_OPCUA_*`` (:class:`twin.furnace.opcua.options.OpcUaOptions`:
allowed endpoints, security, credentials, mapping file, reconnection); their certificates live in
``<data_dir>/opcua``.
"""

from __future__ import annotations

import ipaddress
from pathlib import Path

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from twin.furnace.opcua.options import OpcUaOptions

DEFAULT_DATA_DIR = Path("furnace-data")
#: shortest API token accepted (characters): 16 random characters are beyond guessing over HTTP
MIN_TOKEN_LENGTH = 16


def is_loopback(host: str) -> bool:
    """``localhost`` or a loopback address (127.0.0.0/8, ::1)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Settings(BaseSettings):
    """Where the server listens, where it keeps its data and what it allows."""

    model_config = SettingsConfigDict(env_prefix="FURNACE_TWIN_", frozen=True, extra="ignore")

    data_dir: Path = Field(DEFAULT_DATA_DIR, description="SQLite database and one folder per run")
    host: str = Field("127.0.0.1", description="REST / dashboard bind address (loopback by default)")
    port: int = Field(8000, ge=0, le=65535)
    viser_port: int = Field(8080, ge=0, le=65535, description="viser 3D view; 0 disables it")
    api_token: str | None = Field(None, description="when set, every mutating endpoint needs it (and every read "
                                                    f"when the server listens beyond loopback); at least "
                                                    f"{MIN_TOKEN_LENGTH} characters")
    allowed_hosts: list[str] = Field(default_factory=list,
                                     description="Host names besides loopback (and the bind address) the server "
                                                 "answers to, e.g. '[\"furnace.lab\"]': guards against DNS rebinding")
    allowed_origins: list[str] = Field(default_factory=list,
                                       description="origins besides the server's own allowed to change runs "
                                                   "(e.g. '[\"https://proxy.lab\"]')")
    max_body_bytes: int = Field(1 << 20, ge=1024, description="largest request body (bytes); larger -> 413")
    plan_max_s: float = Field(120.0, gt=0, description="wall time a feedforward plan (start or re-plan) may take (s)")
    plan_max_mb: float = Field(1024.0, gt=0, description="memory a feedforward plan may take (MB, estimated "
                                                         "before solving); more -> 422")
    data_quota_mb: float = Field(10240.0, gt=0, description="most the data directory may hold (MB); a run that "
                                                            "would pass it is refused, one that passes it stops")
    min_free_mb: float = Field(512.0, ge=0, description="free disk space (MB) kept on the data directory's disk")
    retention_days: float | None = Field(None, gt=0, description="ended runs older than this are deleted "
                                                                 "(None: kept)")
    max_concurrent_runs: int = Field(2, ge=1, le=64, description="running runs at once; more -> 429")
    max_duration_s: float = Field(3600.0, gt=0, description="longest simulated run accepted (s)")
    max_speed: float = Field(1000.0, gt=0, description="largest real-time factor accepted")
    stream_max_hz: float = Field(20.0, gt=0, le=100.0, description="frames per second per client, at most")
    client_queue_frames: int = Field(4, ge=1, le=1000, description="per-client queue; older frames drop")
    client_send_timeout_s: float = Field(10.0, gt=0, description="drop a client that takes no frame this long")
    flush_interval_s: float = Field(2.0, gt=0, description="timeseries / database / recording flush (wall s)")
    recording_image_interval_s: float = Field(0.5, gt=0, description="simulated s between field images in the .rrd")
    change_timeout_s: float = Field(5.0, gt=0, description="how long a PUT waits for its re-plan before it answers "
                                                          "'pending' (HTTP clients give up at 10 s)")
    rerun_connect: str | None = Field(None, description="stream every run live to this rerun viewer or gRPC proxy, "
                                                        "e.g. rerun+http://127.0.0.1:9876/proxy")
    rerun_web_port: int = Field(9090, ge=0, le=65535, description="rerun web viewer (loopback); 0 disables it")
    rerun_grpc_port: int = Field(9877, ge=1, le=65535, description="the rerun web viewer's gRPC proxy (loopback)")
    rerun_server_memory_limit: str = Field("512MiB", description="what the rerun proxy buffers for late viewers")
    rerun_memory_limit: str = Field("2GiB", description="what the rerun viewer keeps; the oldest data goes first")
    opcua: OpcUaOptions = Field(default_factory=OpcUaOptions,
                                description="furnaces over OPC UA (environment FURNACE_TWIN_OPCUA_*)")
    opcua_results_endpoint: str | None = Field(
        None, description="serve the twin's own results read-only at this opc.tcp:// endpoint "
                          "(serve --opcua-endpoint); off by default; security as FURNACE_TWIN_OPCUA_SECURITY")
    study_workers: int | None = Field(None, ge=1, le=256,
                                      description="LocalCluster process workers of a study (default: one per core)")
    study_scheduler: str | None = Field(None, description="run studies on this Dask scheduler instead, "
                                        "e.g. tcp://127.0.0.1:8786")
    max_study_cases: int = Field(5000, ge=1, le=100_000, description="largest study accepted (cases)")

    @field_validator("api_token")
    @classmethod
    def _token_length(cls, v: str | None) -> str | None:
        if not v:  # FURNACE_TWIN_API_TOKEN= (empty): no token
            return None
        if len(v) < MIN_TOKEN_LENGTH:
            raise ValueError(f"the API token must have at least {MIN_TOKEN_LENGTH} characters, got {len(v)}")
        return v or None

    @model_validator(mode="after")
    def _results_endpoint(self) -> Settings:
        """The results server's endpoint is an opc.tcp:// URL; beyond loopback only with security."""
        if self.opcua_results_endpoint:
            from twin.endpoints import parse_endpoint

            ep = parse_endpoint(self.opcua_results_endpoint)  # ValueError naming what is wrong
            if self.opcua.security == "none" and not is_loopback(ep.host):
                raise ValueError(f"serving the twin's results over OPC UA on {ep.host} (not a loopback address) "
                                 "needs FURNACE_TWIN_OPCUA_SECURITY=sign-encrypt")
        return self

    @property
    def reads_need_token(self) -> bool:
        """With a token and a non-loopback address, reads (GET, the stream) need the token too."""
        return bool(self.api_token) and not is_loopback(self.host)

    @property
    def db_path(self) -> Path:
        return self.data_dir / "runs.sqlite3"

    @property
    def runs_dir(self) -> Path:
        return self.data_dir / "runs"

    @property
    def studies_dir(self) -> Path:
        return self.data_dir / "studies"
