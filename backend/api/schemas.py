"""Response schemas of the REST API (the request bodies are ``twin.scenario`` models)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from backend.storage.repository import MAX_LABEL_CHARS


class RadiationProgress(BaseModel):
    stage: str = Field(description="waiting, loading the cache, ray tracing, building the model, then loading or "
                                   "ray tracing the simulated furnace's own table, ready or failed")
    done: int = Field(description="table positions ray-traced so far")
    total: int = Field(description="table positions (0 until known)")
    fraction: float = Field(ge=0.0, le=1.0)
    elapsed_s: float
    remaining_s: float | None = Field(None, description="seconds left in the current ray trace at its pace so far "
                                                        "(null before its first position)")
    error: str | None = Field(None, description="why it failed (a worker's error, exit or stall); "
                                                "POST /api/radiation/retry starts it again")


class Health(BaseModel):
    status: str = Field(description="'ok' while the server answers")
    radiation: Literal["ready", "computing", "failed"] = Field(
        description="the radiation model: runs posted while 'computing' wait as 'queued'")
    radiation_progress: RadiationProgress | None = None
    active_runs: int = Field(description="runs this server drives: queued, starting or running")
    queued_runs: int = Field(0, description="of those, the runs still waiting (for the radiation model)")
    max_concurrent_runs: int
    viser_url: str | None = Field(None, description="the 3D view, when it runs")
    rerun_url: str | None = Field(None, description="the rerun web viewer served by this server (/rerun/), when it "
                                                    "runs (a run's recording: its links.rerun)")
    auth_required: bool = Field(description="mutating endpoints need the API token")
    disk: dict[str, Any] = Field(default_factory=dict,
                                 description="data directory: used_mb, free_mb (its disk), quota_mb, min_free_mb, "
                                             "retention_days")
    reads_need_token: bool = Field(False, description="every /api read and the stream need the token too "
                                                      "(the server listens beyond loopback)")


class RunLinks(BaseModel):
    self: str
    stream: str
    metrics: str
    recording: str
    timeseries: str
    faults: str
    rerun: str | None = Field(None, description="'Open in rerun': the server's rerun web viewer on this run "
                                                "(live: its proxy; ended: its recording); null without a viewer")


class RunCreated(BaseModel):
    id: str
    status: str
    links: RunLinks
    warnings: list[str] = Field(default_factory=list,
                                description="what the feasibility check found (the run starts anyway)")
    replayed: bool = Field(False, description="true when this answers a repeated request id (Idempotency-Key): "
                                              "the run the first request started")


class ChangeOut(BaseModel):
    id: int
    kind: str = Field(description="'reference', 'oscillation' or 'faults'")
    body: dict[str, Any]
    requested_at: float = Field(description="unix s")
    status: str = Field(description="pending, applied, superseded (a later change of its kind won before it "
                                    "was planned), rejected or failed (not applied), or cancelled (the run ended)")
    applied_t: float | None = Field(None, description="simulated time of the first sample that uses it (s)")
    message: str | None = None


class ChangeResult(BaseModel):
    id: int
    kind: str
    status: str = Field(description="'applied' (in force from applied_t), 'superseded' (a later change of its "
                                    "kind won), or 'pending' (202: the re-plan outlasted the wait; the outcome "
                                    "comes in the stream's events and GET /api/runs/{id})")
    body: dict[str, Any]
    applied_t: float | None = None
    replan_s: float | None = Field(None, description="wall time from hand-over to the plan in force (s)")
    message: str | None = None
    warnings: list[str] = Field(default_factory=list, description="feasibility of a new reference")


class RunStoryOut(BaseModel):
    """A run by what happened (``backend.runs.story``)."""

    reference: str = Field(description="'1050 K / 30 s (changed at 7.6 s)'")
    oscillation: str = Field(description="'on from 12.0 s (48 mm / 18 s)', 'off', 'on (48 mm / 18 s)'")
    auto_label: str = Field(description="a name for a run without a label: 'fixed', 'osc 48 mm / 18 s'")
    text: str = Field(description="one line: reference · osc oscillation")


class RunSummary(BaseModel):
    id: str
    status: str = Field(description="queued, starting, running, degraded (going, but no thermocouple reading has "
                                    "reached the estimate for a while), or how it ended: finished, degraded (blind "
                                    "at its end), stopped, plant_lost, interrupted or error")
    status_reason: str | None = Field(None, description="why: the outages of a run, the blind spell, the error")
    created_at: float = Field(description="unix s")
    started_at: float | None = None
    ended_at: float | None = None
    scenario: dict[str, Any]
    latest: dict[str, Any] | None = Field(None, description="latest scalar values (t, T_ref, T_mean_hat, ...)")
    metrics: dict[str, Any] | None = Field(None, description="product.md metrics (calibration, shadow: objects)")
    error: str | None = None
    label: str | None = Field(None, description="the user's name for the run (PATCH /api/runs/{id})")
    story: RunStoryOut | None = Field(None, description="what happened: the reference and oscillation in force at "
                                                        "the end (or now), live changes marked, an automatic label")
    files: dict[str, bool] = Field(default_factory=dict, description="which run files exist (recording, timeseries, "
                                                                     "metrics): an interrupted run may have none")
    links: RunLinks


#: printable characters (``clean_label``), for the schema: whitespace (folded to one space), ASCII and Latin-1
#: letters and signs; the server also takes other printable Unicode
LABEL_PATTERN = r"^[\s!-~\u00a1-\u00ac\u00ae-\u00ff]*$"


class LabelIn(BaseModel):
    """``PATCH /api/runs/{id}``: the run's name (null or empty: none)."""

    label: str | None = Field(None, description="at most 80 characters",
                              json_schema_extra={"maxLength": MAX_LABEL_CHARS, "pattern": LABEL_PATTERN})


class RunDetail(RunSummary):
    reference: dict[str, Any] = Field(description="the reference in force now (after live changes); "
                                                  "for an ended run, the last one in force")
    oscillation: dict[str, Any] = Field(description="the oscillation in force now, likewise")
    faults: list[dict[str, Any]] = Field(default_factory=list, description="the faults injected into the simulated "
                                                                           "furnace ('at' in run time), likewise")
    fault_events: list[dict[str, Any]] = Field(default_factory=list,
                                               description="faults injected, cleared and detected by the twin: "
                                                           "[{t (s), text}], oldest first")
    changes: list[ChangeOut] = Field(default_factory=list)
    windows: dict[str, Any] | None = Field(None, description="the metric windows: {t0, t_E, setpoint, transient: "
                                                             "[a, b], steady: [a, b]}, from the last reference change")


class StopResult(BaseModel):
    id: str
    status: str = Field(description="'stopping': the run ends at its next sample and keeps its data")


class LampGroupOut(BaseModel):
    name: str
    lamps: list[str] = Field(description="'h3' = 3rd horizontal lamp, 'v-1' = last vertical lamp, ...")


class FurnaceOut(BaseModel):
    """The loaded furnace: what the dashboard draws and every scenario limit and default."""

    name: str = Field(description="shipped furnace name or file stem; 'custom' if unknown")
    L_s: float = Field(description="specimen length (m)")
    W_s: float = Field(description="specimen width (m)")
    B_s: float = Field(description="specimen thickness (m)")
    nx: int = Field(description="FD cells along x")
    ny: int = Field(description="FD cells along y")
    x: list[float] = Field(description="cell centres along x (m)")
    y: list[float] = Field(description="cell centres along y (m)")
    fillet: list[float] = Field(description="x0, x1, y0, y1 of the fillet (m)")
    eta_max: float = Field(description="largest oscillation amplitude (m)")
    t_s: float = Field(description="sampling time (s)")
    lamps: dict[str, Any] = Field(description="lamp arrays: count, pitch, distance (m) per side")
    tc_relative: list[list[float]] = Field(description="TC1..TC4 (x / L_s, y / W_s); TC4 is the validation TC")
    tc_positions: list[list[float]] = Field(description="TC1..TC4 in m")
    calibration_bounds: dict[str, list[float]] = Field(
        default_factory=dict, description="calibrated parameters: [low, high] relative deviation from the model "
                                          "that the calibrating estimator holds each within")
    groups: list[LampGroupOut] = Field(description="lamp groups, in the order of the power vector u")
    limits: dict[str, Any] = Field(description="every scenario limit and default, in the shape of a scenario: "
                                               "{min, max, exclusive_min, unit, default}")
    defaults: dict[str, Any] = Field(description="the scenario a POST with an empty body starts")


class StudyLinks(BaseModel):
    self: str
    stop: str
    resume: str
    files: str = Field(description="prefix of the study's files: results.parquet, results.csv, study.md, "
                                   "summary.json, figures/<name>.png")


class StudySummary(BaseModel):
    id: str
    name: str | None = None
    furnace: str
    status: str = Field(description="queued, running, finished, stopped, interrupted or error")
    created_at: float = Field(description="unix s")
    started_at: float | None = None
    ended_at: float | None = None
    total: int = Field(description="cases of the study")
    finished: int = Field(description="cases done or failed, including those found done earlier")
    failed: int
    skipped: int = Field(description="cases found done by an earlier invocation (resume)")
    workers: int = Field(description="Dask workers of the current or last invocation")
    error: str | None = None
    links: StudyLinks


class StudyPlan(BaseModel):
    cases: int = Field(description="cases a start would run: design points x seeds or Monte Carlo samples")
    points: int = Field(description="design points (the grid without its seed field)")
    per_point: int = Field(description="cases per design point (seeds x samples)")
    workers: int = Field(description="Dask workers the server's studies get")
    estimate_s: float | None = Field(description="estimated wall time (s), from this server's finished studies; "
                                                 "null before any")
    basis: str | None = Field(description="what the estimate is scaled from, or why there is none")


class StudyDetail(StudySummary):
    study: dict[str, Any] = Field(description="the study document as posted")
    cases: list[dict[str, Any]] | None = Field(
        None, description="per case: key, index, params, status, metrics, error (when the study has ended)")
    best: list[dict[str, Any]] = Field(
        default_factory=list,
        description="per metric: the design points' range (min, max), the seed-to-seed spread, the best point and "
                    "the next, whether the best beats the next by more than the spread (decided), the reading")
    percentiles: dict[str, dict[str, float]] | None = Field(None, description="Monte Carlo: per metric")
    timing: dict[str, Any] | None = None
    figures: list[str] = Field(default_factory=list, description="URLs of the PNG figures")
    downloads: dict[str, str] = Field(default_factory=dict, description="file name -> URL")


class PlacementRequest(BaseModel):
    """``POST /api/placement``: rank TC positions for one specimen mode of the loaded furnace."""

    model_config = {"extra": "forbid"}
    oscillate: bool = Field(False, description="the nominal run oscillates (the position-aware model)")


class PlacementPosition(BaseModel):
    rank: int = Field(ge=1, description="1: the greedy choice's first")
    x: float = Field(description="m along the specimen's length")
    y: float = Field(description="m across")
    x_rel: float = Field(description="x / L_s")
    y_rel: float = Field(description="y / W_s")
    score: float = Field(description="information about the fillet's nodes of the positions up to this rank (nats)")


class PlacementPaper(BaseModel):
    positions: list[list[float]] = Field(description="the paper's TC1-3 (x / L_s, y / W_s)")
    score: float = Field(description="their information about the fillet's nodes (nats)")


class PlacementMap(BaseModel):
    x_rel: list[float] = Field(description="each candidate's x / L_s (the FE nodes off the edges and clamps)")
    y_rel: list[float] = Field(description="each candidate's y / W_s")
    score: list[float] = Field(description="the information of one TC at that candidate alone (nats)")


class PlacementOut(BaseModel):
    furnace: str
    oscillate: bool
    state: Literal["computing", "done", "failed"]
    count: int = Field(ge=1, description="positions asked for (the first `count` of the greedy ranking)")
    seconds: float | None = Field(None, description="how long the ranking took (null while computing)")
    error: str | None = Field(None, description="why it failed; POST again to retry")
    criterion: str | None = None
    positions: list[PlacementPosition] = Field(default_factory=list, description="best first (empty until done)")
    paper: PlacementPaper | None = None
    map: PlacementMap | None = None
