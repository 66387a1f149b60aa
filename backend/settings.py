"""Server settings of the live dashboard (pydantic-settings, env prefix ``FURNACE_TWIN_``).

Every field can be set from the environment, e.g. ``FURNACE_TWIN_API_TOKEN=secret`` or
``FURNACE_TWIN_MAX_CONCURRENT_RUNS=3``; ``furnace-twin serve`` passes host, ports and the
data directory explicitly.  The defaults bind to loopback only.  Runs on a furnace over OPC UA take
their link settings from ``FURNACE_TWIN_OPCUA_*`` (:class:`twin.furnace.opcua.options.OpcUaOptions`:
allowed endpoints, security, credentials, mapping file, reconnection); their certificates live in
``<data_dir>/opcua``.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from twin.furnace.opcua.options import OpcUaOptions

DEFAULT_DATA_DIR = Path("furnace-data")


class Settings(BaseSettings):
    """Where the server listens, where it keeps its data and what it allows."""

    model_config = SettingsConfigDict(env_prefix="FURNACE_TWIN_", frozen=True, extra="ignore")

    data_dir: Path = Field(DEFAULT_DATA_DIR, description="SQLite database and one folder per run")
    host: str = Field("127.0.0.1", description="REST / dashboard bind address (loopback by default)")
    port: int = Field(8000, ge=0, le=65535)
    viser_port: int = Field(8080, ge=0, le=65535, description="viser 3D view; 0 disables it")
    api_token: str | None = Field(None, description="when set, every mutating endpoint needs it")
    max_concurrent_runs: int = Field(2, ge=1, le=64, description="running runs at once; more -> 429")
    max_duration_s: float = Field(3600.0, gt=0, description="longest simulated run accepted (s)")
    max_speed: float = Field(1000.0, gt=0, description="largest real-time factor accepted")
    stream_max_hz: float = Field(20.0, gt=0, le=100.0, description="frames per second per client, at most")
    client_queue_frames: int = Field(4, ge=1, le=1000, description="per-client queue; older frames drop")
    client_send_timeout_s: float = Field(10.0, gt=0, description="drop a client that takes no frame this long")
    flush_interval_s: float = Field(2.0, gt=0, description="timeseries / database / recording flush (wall s)")
    recording_image_interval_s: float = Field(0.5, gt=0, description="simulated s between field images in the .rrd")
    change_timeout_s: float = Field(60.0, gt=0, description="how long a PUT waits for its re-plan")
    opcua: OpcUaOptions = Field(default_factory=OpcUaOptions,
                                description="furnaces over OPC UA (environment FURNACE_TWIN_OPCUA_*)")

    @property
    def db_path(self) -> Path:
        return self.data_dir / "runs.sqlite3"

    @property
    def runs_dir(self) -> Path:
        return self.data_dir / "runs"
