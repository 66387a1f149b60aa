"""Can the furnace follow a reference?  Checked on the reduced model before a run starts (or a change applies).

Two questions, both answered with the discrete model (eq. 12a) that the controller itself uses:

* **What can it hold?**  :func:`hold_range`: the fillet means (c_m^T theta, eq. 19) of the model's
  steady states with every group off (u = 0) and at full power (u = 1).  The lower end is *not* the
  coldest surrounding: with the lamps off the holders, reflectors and housing still warm the
  specimen, so the default furnace settles near 480 K, and a setpoint below that cannot be held.
* **How fast can it heat and cool?**  :func:`check_reference` simulates the fillet mean that
  follows the reference as closely as the lamps allow: at each sample the uniform power
  fraction s in [0, 1] (every group at s u_max) that puts the next mean on the reference,
  clipped to [0, 1].  Because F is affine in u (eq. 12a), s follows from one step of the
  model; at s = 1 the mean heats as fast as the furnace can, at s = 0 it cools as fast as it
  can (lamps off).  The gap between the reference and that best mean is the *shortfall*
  (positive: the reference is hotter than the furnace can be; negative: colder).

The verdict (:class:`Feasibility`): ``ok`` when the shortfall stays within ``WARN_K``;
``warn`` (the run starts, the page and the run's events say when and by how much) when it
exceeds it; ``refuse`` (``POST /api/runs`` answers 422) when it is impossible by a wide
margin: a shortfall above ``REFUSE_FRACTION`` of the reference's excursion and above
``REFUSE_MIN_K``, or a final temperature to hold more than ``REFUSE_MIN_K`` outside
:func:`hold_range`.  A 0 s step to 1300 K, t_E = 1.2 s to 1100 K and 300 -> 1300 K in 1 s are
refused; the paper's 1100 K in 120 s is ok.  The feedback needs some headroom on top, so a
reference that is only just feasible may still saturate single groups during the run (the
run reports those; :mod:`twin.control.saturation`).

Example
-------
>>> from twin.config import small_config
>>> from twin.radiation import radiation_model
>>> from twin.model.discrete import discrete_model
>>> from twin.scenario import TransitionReference
>>> cfg = small_config()
>>> model = discrete_model(cfg, radiation_model(cfg), None)
>>> ok = check_transition(model, cfg, TransitionReference(setpoint=1100.0, t_E=120.0), duration=240.0)
>>> ok.verdict, ok.messages
('ok', ())
>>> bad = check_transition(model, cfg, TransitionReference(setpoint=1100.0, t_E=1.2), duration=240.0)
>>> bad.verdict, bad.worst.t <= 1.3
('refuse', True)
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.control.reference import ReferenceTrajectory, reference_trajectory, steady_state
from twin.model.dynamics import DiscreteDynamics
from twin.scenario import PointsReference, Reference, TransitionReference

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

WARN_K = 3.0  # a shortfall above this (K) is worth a warning
REFUSE_FRACTION = 0.5  # ... and refused above this fraction of the reference's excursion
REFUSE_MIN_K = 50.0  # ... when it is also above this many kelvin

Verdict = Literal["ok", "warn", "refuse"]


@dataclass(frozen=True)
class Shortfall:
    """The reference against the best mean the furnace can reach at one time.

    ``shortfall`` = T_ref - T_best (K): positive when the reference is hotter than the furnace can
    heat to by then, negative when it is colder than it can cool to.
    """

    t: float
    T_ref: float
    T_best: float

    @property
    def shortfall(self) -> float:
        return self.T_ref - self.T_best


@dataclass(frozen=True)
class Feasibility:
    """The verdict on one reference, with what the page and the events say about it.

    Attributes
    ----------
    verdict : ``ok``, ``warn`` or ``refuse``
    messages : plain sentences that name the time and the shortfall (empty when ``ok``)
    worst : the time of the largest shortfall (``None`` if the reference never deviates)
    first_t : the first time the shortfall exceeds ``WARN_K`` (s), ``None`` if never
    hold_range : fillet means the furnace can hold (lamps off, full power), K
    t, T_best : the best reachable fillet mean over the run (decimated for display), s and K
    """

    verdict: Verdict
    messages: tuple[str, ...]
    worst: Shortfall | None
    first_t: float | None
    hold_range: tuple[float, float]
    t: Array = field(repr=False, default_factory=lambda: np.zeros(0))
    T_best: Array = field(repr=False, default_factory=lambda: np.zeros(0))

    def to_json(self, max_points: int = 400) -> dict[str, object]:
        """The verdict as JSON (``POST /api/feasibility``, the warnings of ``POST /api/runs``)."""
        step = max(1, math.ceil(len(self.t) / max_points))
        w = self.worst
        return {
            "verdict": self.verdict,
            "messages": list(self.messages),
            "worst": None if w is None else {"t": w.t, "T_ref": w.T_ref, "T_best": w.T_best,
                                             "shortfall": w.shortfall},
            "first_t": self.first_t,
            "hold_range": list(self.hold_range),
            "best": {"t": self.t[::step].tolist(), "T": self.T_best[::step].tolist()},
        }


def hold_range(model: DiscreteDynamics, cfg: FurnaceConfig) -> tuple[float, float]:
    """Fillet means (K) of the model's steady states with all lamps off and all groups at u_max (eq. 19).

    The lower end is the lamps-off steady state: the warm holders and surroundings keep the specimen
    above the coldest surrounding temperature."""
    guess = np.full(model.n, float(cfg.fe.reference_temperature))
    off = steady_state(model, np.zeros(model.m), guess)
    full = steady_state(model, np.ones(model.m), guess)
    return float(model.c_m @ off), float(model.c_m @ full)


def best_tracking(model: DiscreteDynamics, ref: ReferenceTrajectory, theta0: Array, t0: float,
                  n_steps: int, s_max: float = 1.0) -> tuple[Array, Array]:
    """The fillet mean that follows ``ref`` as closely as uniform group powers in [0, s_max] allow.

    Returns the run times t0 .. t0 + n_steps t_s and the mean there (K).  Per sample, with
    F(theta, u) = F(theta, 0) + t_s B(theta) u (eq. 12a, affine in u) and u = s 1:
    s = clip((T_ref(t + t_s) - c_m^T F(theta, 0)) / (c_m^T t_s B(theta) 1), 0, s_max).
    (B depends on theta only in a model with c_p(T), :class:`twin.control.plan_model.CapacityModel`.)
    """
    t_s = float(model.t_s)
    ones = np.ones(model.m)
    t: Array = t0 + t_s * np.arange(n_steps + 1, dtype=float)
    target = np.asarray(ref(t), float)
    theta = np.asarray(theta0, float).copy()
    mean = np.empty(n_steps + 1)
    mean[0] = float(model.c_m @ theta)
    zero = np.zeros(model.m)
    for j in range(n_steps):
        gain_vec = np.asarray(model.jac_u(theta, ones), float) @ ones  # t_s B 1: K per unit s, per node
        gain = float(model.c_m @ gain_vec)
        free = np.asarray(model.step(theta, zero), float)
        s = min(max((target[j + 1] - float(model.c_m @ free)) / gain, 0.0), s_max) if gain > 0 else s_max
        theta = free + s * gain_vec
        mean[j + 1] = float(model.c_m @ theta)
    return t, mean


def _describe(w: Shortfall, hold: tuple[float, float], held: bool) -> str:
    """One sentence about the largest shortfall: when, what the reference asks, what is reachable;
    ``held``: the reference is constant there (after its last change)."""
    when = f"at t = {w.t:.1f} s the reference asks for {w.T_ref:.0f} K"
    if w.shortfall > 0:
        if held and w.T_ref > hold[1] + WARN_K:
            return (f"{when}; this furnace holds at most {hold[1]:.0f} K with every group at full power "
                    f"({w.shortfall:.0f} K short)")
        return (f"{when}, but even at full power the fillet mean reaches only {w.T_best:.0f} K by then "
                f"({w.shortfall:.0f} K short)")
    if held and w.T_ref < hold[0] - WARN_K:
        return (f"{when}, but this furnace cannot hold the fillet mean below {hold[0]:.0f} K (its steady state with "
                f"the lamps off: the warm holders and walls heat the specimen); by then it is {-w.shortfall:.0f} K "
                "above the reference")
    why = " (the warm holders and walls heat it)" if w.T_best <= hold[0] + WARN_K else ""
    return (f"{when}, but even with the lamps off the fillet mean is at {w.T_best:.0f} K by then{why}, "
            f"{-w.shortfall:.0f} K above the reference")


def check_reference(model: DiscreteDynamics, cfg: FurnaceConfig, ref: ReferenceTrajectory, *, T_initial: float,
                    t_start: float, t_end: float, hold: tuple[float, float] | None = None) -> Feasibility:
    """The verdict on ``ref`` from a uniform field at ``T_initial`` (K) at run time ``t_start`` to ``t_end`` (s).

    ``hold`` is :func:`hold_range` of the model (computed if not given; cache it per furnace)."""
    hold = hold_range(model, cfg) if hold is None else hold
    n = max(int(math.ceil((t_end - t_start) / model.t_s - 1e-9)), 1)
    t, best = best_tracking(model, ref, np.full(model.n, float(T_initial)), t_start, n)
    T_ref = np.asarray(ref(t), float)
    gap = T_ref - best
    k = int(np.argmax(np.abs(gap)))
    worst = Shortfall(float(t[k]), float(T_ref[k]), float(best[k])) if abs(gap[k]) > 0 else None
    over = np.flatnonzero(np.abs(gap) > WARN_K)
    if worst is None or not over.size:
        return Feasibility("ok", (), worst, None, hold, t, best)
    first_t = float(t[over[0]])
    excursion = max(float(np.max(np.abs(T_ref - T_initial))), 1.0)
    refuse = abs(worst.shortfall) > max(REFUSE_FRACTION * excursion, REFUSE_MIN_K)
    # a temperature to hold (the reference's last value, reached within the run) that the furnace cannot hold
    held = ref.t_end <= t_end and (ref.T_final < hold[0] - REFUSE_MIN_K or ref.T_final > hold[1] + REFUSE_MIN_K)
    refuse = refuse or held
    messages = [_describe(worst, hold, worst.t >= ref.t_end)]
    if held and worst.t < ref.t_end:  # the sentence above is about the way there: say what cannot be held
        lo_hi = f"below {hold[0]:.0f} K (lamps off)" if ref.T_final < hold[0] else f"above {hold[1]:.0f} K (full power)"
        messages.append(f"its last value, {ref.T_final:.0f} K from t = {ref.t_end:.1f} s, cannot be held: this furnace "
                        f"cannot hold the fillet mean {lo_hi}")
    if first_t < worst.t - model.t_s / 2:
        messages.append(f"the fillet mean departs from the reference from t = {first_t:.1f} s on")
    late = np.flatnonzero(np.abs(gap[k:]) <= WARN_K)
    if late.size:
        messages.append(f"it catches up at t = {float(t[k + late[0]]):.1f} s")
    else:
        messages.append("it does not catch up before the end of the run")
    return Feasibility("refuse" if refuse else "warn", tuple(messages), worst, first_t, hold, t, best)


def shortest_transition(model: DiscreteDynamics, cfg: FurnaceConfig, setpoint: float, T_initial: float,
                        hold: tuple[float, float], *, hi: float = 3600.0) -> float | None:
    """The shortest t_E (s, to 5 %) of the paper's transition to ``setpoint`` that the model follows within
    ``WARN_K``; ``None`` if no t_E up to ``hi`` does (the setpoint cannot be held).

    Only a lag in the direction of travel counts (the mean behind a heating reference, above a cooling one): a
    mean that runs ahead of a slow reference's start by itself (the warm holders and walls heat the cold plate
    with the lamps off, more so on a model with c_p(T)) does so for every t_E and says nothing about speed."""
    if not hold[0] - WARN_K <= setpoint <= hold[1] + WARN_K:
        return None
    direction = 1.0 if setpoint >= T_initial else -1.0

    def follows(t_E: float) -> bool:
        ref = reference_trajectory(TransitionReference(setpoint=setpoint, t_E=t_E), T_initial)
        n = int(math.ceil(1.2 * t_E / model.t_s)) + 1
        t, best = best_tracking(model, ref, np.full(model.n, float(T_initial)), 0.0, n)
        return bool(np.max(direction * (np.asarray(ref(t)) - best)) <= WARN_K)

    lo, top = 1.0, 10.0  # t_E > 1 s (twin.limits)
    while not follows(top):  # doubling: each try simulates about 1.2 t_E
        lo, top = top, 2.0 * top
        if top > hi:
            return None
    while top / lo > 1.05:
        mid = math.sqrt(lo * top)
        lo, top = (lo, mid) if follows(mid) else (mid, top)
    return top


def reserve_note(model: DiscreteDynamics, ref: ReferenceTrajectory, T_initial: float, t_start: float,
                 t_end: float, limit: float, full: Feasibility) -> str | None:
    """A sentence when the reference needs more than the feedforward's share ``limit`` of u_max
    (``[control] feedforward_limit``) although the furnace can follow it at full power: then the feedback
    spends its reserve on the plan, and has less for the furnace's surprises."""
    if limit >= 1.0 or full.verdict == "refuse":
        return None
    n = max(int(math.ceil((t_end - t_start) / model.t_s - 1e-9)), 1)
    t, capped = best_tracking(model, ref, np.full(model.n, float(T_initial)), t_start, n, s_max=limit)
    gap = np.asarray(ref(t), float) - capped
    extra = gap - (np.asarray(ref(t), float) - full.T_best) if full.T_best.size == gap.size else gap
    k = int(np.argmax(extra))
    if extra[k] <= WARN_K:
        return None
    return (f"the plan may use {limit:.0%} of each group's power (the rest is the feedback's reserve): with that "
            f"the fillet mean would fall {gap[k]:.0f} K behind at t = {t[k]:.1f} s, so the feedback spends its "
            "reserve on the plan there")


def check_transition(model: DiscreteDynamics, cfg: FurnaceConfig, spec: Reference, *, duration: float,
                     T_initial: float | None = None, t_start: float = 0.0,
                     hold: tuple[float, float] | None = None, limit: float | None = None) -> Feasibility:
    """:func:`check_reference` of a scenario's reference (transition or points) over a run of ``duration`` s
    from ``t_start`` (a live change: from now, with the current mean as ``T_initial``); adds what a
    user can change: the shortest feasible t_E of a transition, points after the end of the run, and (``limit``,
    default ``[control] feedforward_limit``) where the plan would need the feedback's reserve."""
    T0 = float(cfg.specimen.initial_temperature) if T_initial is None else float(T_initial)
    hold = hold_range(model, cfg) if hold is None else hold
    ref = reference_trajectory(spec, T0, t_start=t_start)
    t_end = max(duration, t_start + model.t_s)
    out = check_reference(model, cfg, ref, T_initial=T0, t_start=t_start, t_end=t_end, hold=hold)
    extra: list[str] = []
    note = reserve_note(model, ref, T0, t_start, t_end,
                        float(cfg.control.feedforward_limit if limit is None else limit), out)
    if note is not None:
        extra.append(note)
    if isinstance(spec, TransitionReference) and out.verdict != "ok":
        shortest = shortest_transition(model, cfg, spec.setpoint, T0, hold)
        if shortest is not None and shortest > spec.t_E:
            extra.append(f"the shortest transition to {spec.setpoint:.0f} K this furnace can follow takes "
                         f"about {shortest:.0f} s (t_E)")
    if isinstance(spec, PointsReference) and t_start + spec.points[-1][0] > duration + 1e-9:
        extra.append(f"the last reference point (t = {t_start + spec.points[-1][0]:g} s) lies after the end of "
                     f"the run ({duration:g} s): the run ends before the reference does")
    if not extra:
        return out
    verdict: Verdict = "warn" if out.verdict == "ok" else out.verdict
    return Feasibility(verdict, out.messages + tuple(extra), out.worst, out.first_t, out.hold_range, out.t,
                       out.T_best)
