"""Stream frames (product.md, "Stream frame"): one JSON object per published closed-loop sample.

Keys of the contract: ``t`` (s), ``eta`` (m), ``T_ref``, ``T_mean_hat`` (K, fillet mean of the
estimate), ``field`` (estimated temperature, N_y rows x N_x columns, K), ``tc``, ``tc_hat``
(the four TC readings and the estimate there, K), ``u``, ``u_ff`` (six group powers, fractions
of u_max), ``inhomogeneity`` (K).  Added: ``run_id``, ``seq`` (sample counter), ``wall_time``
(unix s when the sample was computed, for latency), ``status``, ``events`` (texts of the run's
events since the previous frame), ``late_samples`` (samples of a real-time furnace whose readings did
not all come in time, so far), and from the server (``backend.runs.manager``): ``event_log``
(those events as ``{n, t, text, level}``, ``n`` their index in the run's event list, so a page
that also read ``GET /api/runs/{id}/series`` shows each one once), ``spread`` (max over the fillet
|T_hat - fillet mean|, K) and ``saturated`` (per group: +1 at full power, -1 off, 0 in between).  With a calibrating
estimator ``calibration`` ({name: {"value", "sigma"}}, relative deviations), with a shadow
estimator ``shadow`` ({"T_mean_hat", "tc_hat", "field_delta": shadow minus estimate, N_y x N_x, K}).
The estimate's uncertainty (issue 25): ``sigma_mean`` (K, standard deviation of ``T_mean_hat``), ``nis``
and ``field_sigma`` (standard deviation of ``field``, N_y x N_x, K), when the run reports them.
"""

from __future__ import annotations

import json
from typing import Any, Protocol

import numpy as np

from twin.jsonable import finite_or_none
from twin.model.tables import PARAMETERS

FIELD_DECIMALS = 2  # K; the estimate is not better than 0.01 K, and it keeps frames small


class SnapshotLike(Protocol):
    """What the backend reads from ``twin.runs.record.Snapshot`` (docs/interfaces.md); read-only."""

    @property
    def t(self) -> float: ...
    @property
    def eta(self) -> float: ...
    @property
    def T_ref(self) -> float: ...
    @property
    def T_mean_hat(self) -> float: ...
    @property
    def field_hat(self) -> Any: ...
    @property
    def field_true(self) -> Any: ...  # None for a furnace without a true field
    @property
    def tc(self) -> Any: ...
    @property
    def tc_hat(self) -> Any: ...
    @property
    def u(self) -> Any: ...
    @property
    def u_ff(self) -> Any: ...
    @property
    def inhomogeneity(self) -> float: ...
    @property
    def true_mean(self) -> float | None: ...
    @property
    def true_inhomogeneity(self) -> float | None: ...
    @property
    def events(self) -> Any: ...
    @property
    def blind_since(self) -> float | None: ...  # run time since which no TC reading reached the estimate
    @property
    def parameters(self) -> Any: ...  # (3,) calibrated deviations or None
    @property
    def parameter_sigma(self) -> Any: ...
    @property
    def shadow_T_mean_hat(self) -> float | None: ...
    @property
    def shadow_tc_hat(self) -> Any: ...
    @property
    def shadow_field_hat(self) -> Any: ...
    @property
    def late_samples(self) -> int: ...
    @property
    def field_sigma(self) -> Any: ...  # (N_y, N_x) K or None
    @property
    def sigma_mean(self) -> float | None: ...
    @property
    def nis(self) -> float | None: ...



def _vector(a: Any, decimals: int = 4) -> list[float | None]:
    return [finite_or_none(round(float(v), decimals)) for v in np.asarray(a, dtype=float).ravel()]


def events_of(ev: Any) -> list[str]:
    """A snapshot's ``events`` (None, one string or a sequence) as a list of strings."""
    if ev is None:
        return []
    if isinstance(ev, str):
        return [ev]
    return [str(e) for e in ev]


def calibration_values(s: SnapshotLike) -> dict[str, dict[str, float | None]] | None:
    """{name: {"value", "sigma"}} of the calibrated parameters of a snapshot, or None."""
    if s.parameters is None:
        return None
    values = np.asarray(s.parameters, dtype=float)
    sigma = np.asarray(s.parameter_sigma if s.parameter_sigma is not None else np.full(len(values), np.nan), float)
    return {name: {"value": finite_or_none(values[i]), "sigma": finite_or_none(sigma[i])}
            for i, name in enumerate(PARAMETERS) if np.isfinite(values[i])}


def scalar_values(s: SnapshotLike) -> dict[str, Any]:
    """The small part of a snapshot (no fields): stored as the run's latest values."""
    out = _scalars(s)
    calibration = calibration_values(s)
    if calibration is not None:
        out["calibration"] = calibration
    if getattr(s, "sigma_mean", None) is not None:
        out["sigma_mean"] = finite_or_none(s.sigma_mean)
        out["nis"] = finite_or_none(s.nis)
    if s.shadow_T_mean_hat is not None:
        out["shadow"] = {"T_mean_hat": finite_or_none(s.shadow_T_mean_hat), "tc_hat": _vector(s.shadow_tc_hat)}
    return out


def _scalars(s: SnapshotLike) -> dict[str, Any]:
    return {
        "t": float(s.t),
        "eta": float(s.eta),
        "T_ref": finite_or_none(s.T_ref),
        "T_mean_hat": finite_or_none(s.T_mean_hat),
        "tc": _vector(s.tc),
        "tc_hat": _vector(s.tc_hat),
        "u": _vector(s.u),
        "u_ff": _vector(s.u_ff),
        "inhomogeneity": finite_or_none(s.inhomogeneity),
        "true_mean": finite_or_none(s.true_mean),
        "true_inhomogeneity": finite_or_none(s.true_inhomogeneity),
        "late_samples": int(s.late_samples),
    }


def frame_extra(s: SnapshotLike, fillet: Any) -> dict[str, Any]:
    """What the server adds to a frame: ``spread`` (max over the fillet |T_hat - fillet mean|, K, with a
    ``twin.physics.fillet.Fillet``) and ``saturated`` (+1 full power, -1 off, 0 between, per group)."""
    from twin.control.saturation import bound_flags

    return {"spread": finite_or_none(fillet.spread(s.field_hat)), "saturated": bound_flags(s.u).tolist()}


def frame_dict(s: SnapshotLike, *, run_id: str, seq: int, wall_time: float, status: str,
               events: list[str] | None = None, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """The frame of one snapshot; ``events`` replaces the snapshot's own (the events of every sample
    since the previous frame, so none is lost when samples are not streamed one by one)."""
    field = np.round(np.asarray(s.field_hat, dtype=float), FIELD_DECIMALS)
    frame = scalar_values(s)
    frame.update(
        run_id=run_id,
        seq=seq,
        wall_time=wall_time,
        status=status,
        field=_grid(field),
        events=events_of(s.events) if events is None else list(events),
    )
    sigma = getattr(s, "field_sigma", None)
    if sigma is not None:
        frame["field_sigma"] = _grid(np.round(np.asarray(sigma, dtype=float), FIELD_DECIMALS))
    shadow_field = s.shadow_field_hat
    if shadow_field is not None and "shadow" in frame:
        delta = np.round(np.asarray(shadow_field, dtype=float) - np.asarray(s.field_hat, dtype=float), FIELD_DECIMALS)
        frame["shadow"]["field_delta"] = _grid(delta)
    if extra:
        frame.update(extra)
    return frame


def _grid(field: Any) -> list[list[float | None]]:
    f = np.asarray(field, dtype=float)
    return [[finite_or_none(v) for v in row] for row in np.where(np.isfinite(f), f, np.nan)]


def frame_json(s: SnapshotLike, *, run_id: str, seq: int, wall_time: float, status: str,
               events: list[str] | None = None, extra: dict[str, Any] | None = None) -> str:
    """The frame as JSON text, serialised once and sent to every client."""
    return json.dumps(frame_dict(s, run_id=run_id, seq=seq, wall_time=wall_time, status=status, events=events,
                                 extra=extra), allow_nan=False, separators=(",", ":"))

