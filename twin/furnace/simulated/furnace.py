"""The simulated furnace: the full-order plant, its thermocouples and the specimen drive behind the
furnace boundary (:class:`twin.furnace.interface.Furnace`).

It is the "truth" of a simulated run: the plant (eqs. 1-6), Gaussian TC noise from the run's seed,
and eta(t) of the oscillation in force.  Built for a scenario (:meth:`SimulatedFurnace.for_scenario`)
it is, by default, not the twin's model: its own exchange factors, latent heat in c_p, lagging and
biased thermocouples, lagging lamps and deviations of emissivity, convection and lamp efficiency
(:mod:`twin.furnace.simulated.truth`, the furnace file's ``[truth]``); with ``"truth": "shared"``
it is the plant on the model's own tables with ideal sensors and lamps.  Time advances only through
:meth:`SimulatedFurnace.apply`: each call integrates the plant over one sample with the powers held,
so samples are read and applied in order (t_j, t_j + t_s, ...).

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> furnace = SimulatedFurnace(small_config(), radiation=None, tc_noise=0.0)
>>> furnace.read(0.0).values.tolist()
[300.0, 300.0, 300.0, 300.0]
>>> furnace.apply(np.zeros(6), 0.0)
>>> r = furnace.read(0.1)
>>> r.status, bool(furnace.true_field().shape == (442,))
(('good', 'good', 'good', 'good'), True)
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.furnace.interface import Motion, Readings
from twin.furnace.simulated.faults import FaultInjector
from twin.furnace.simulated.plant import Plant
from twin.furnace.simulated.sensors import LaggedThermocouples, LampLag
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.furnace.simulated.truth import Truth, deviations
from twin.physics.motion import eta_function
from twin.scenario import FaultSpec, Mismatch, OscillationSpec, Scenario

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class SimulatedFurnace:
    """Plant + thermocouples + specimen drive, the :class:`twin.furnace.interface.Furnace` of a simulation.

    Parameters
    ----------
    cfg : the furnace
    radiation : the plant's radiation model (``None``: no radiation, for tests)
    mismatch : the plant's relative deviations from the nominal model (all of them: with a ``truth``,
        :func:`twin.furnace.simulated.truth.deviations` adds the furnace's own to a scenario's)
    tc4 : relative position (x / L_s, y / W_s) of the validation thermocouple TC4
    tc_noise : TC noise standard deviation (K)
    seed : of the TC noise
    oscillation : the drive's settings at t = 0
    T0 : initial cell temperatures (K); default the configured uniform initial temperature
    truth : the furnace's latent heat, TC and lamp dynamics (``None``: the model's c_p, ideal TCs and lamps)
    faults : faults injected at run time (:mod:`twin.furnace.simulated.faults`)
    other_tc4 : further relative places of TC4, read beside it (:meth:`other_tc4_readings`): each as TC4
        would read there in a run of its own, so one run serves the campaign's TC4 places (TC4 only validates:
        the twin never uses it, :data:`twin.furnace.interface.N_ESTIMATOR_TCS`)
    """

    kind = "simulated"
    realtime = False  # no clock of its own: time moves on with apply()

    def __init__(
        self,
        cfg: FurnaceConfig,
        radiation: Any,
        *,
        mismatch: Mismatch | None = None,
        tc4: tuple[float, float] | None = None,
        tc_noise: float = 1.0,
        seed: int = 0,
        oscillation: OscillationSpec | None = None,
        T0: ArrayLike | None = None,
        truth: Truth | None = None,
        faults: Sequence[FaultSpec] = (),
        other_tc4: Sequence[tuple[float, float]] = (),
    ) -> None:
        self.cfg = cfg
        self.truth = truth
        self.plant = Plant(cfg if truth is None else truth.plant_cfg, radiation, mismatch)
        positions: Sequence[tuple[float, float]] = cfg.tc_positions(tc4)
        self.thermocouples = Thermocouples(cfg, positions)
        self._tc_noise = float(tc_noise)
        self._rng = np.random.default_rng(seed)
        T_init = np.full(self.plant.n, cfg.specimen.initial_temperature) if T0 is None else T0
        self._state = self.plant.start(T_init, 0.0)
        self._T_init = np.array(self._state.T, dtype=float)  # the start, for lamps_off_means
        self._sensors: LaggedThermocouples | None = None
        self._lamps: LampLag | None = None
        if truth is not None:
            self._sensors = LaggedThermocouples(self.thermocouples, self._state.T, seed=seed,
                                                time_constant=truth.tc_time_constant, bias=truth.tc_bias)
            self._lamps = LampLag(cfg.n_groups, time_constant=truth.lamp_time_constant)
        self._oscillation = oscillation or OscillationSpec()
        self._since = 0.0
        self._eta_of_t = eta_function(self._oscillation)
        self._eta_initial = self._eta_of_t
        self.faults = FaultInjector(tuple(g.name for g in cfg.lamps.groups), faults)
        self._others = [_OtherTC4(cfg, place, self._state.T, truth, seed, self.faults) for place in other_tc4]
        # (plant time, readings, the other TC4 places' readings): a repeated read of the same sample gives the same
        self._last_read: tuple[float, Readings, tuple[Readings, ...]] | None = None

    @classmethod
    def for_scenario(cls, cfg: FurnaceConfig, scenario: Scenario, radiation: Any, *,
                     truth_radiation: Any = None, other_tc4: Sequence[tuple[float, float]] = ()) -> SimulatedFurnace:
        """The furnace of a scenario: its truth, mismatch, TC4, TC noise, seed, initial oscillation and faults
        (and ``other_tc4``: TC4 read at these places too, :meth:`other_tc4_readings`).

        ``radiation`` is the twin's model (the plant's tables when the scenario's truth is ``"shared"``);
        ``truth_radiation`` the furnace's own table, read from the cache if not given and needed.
        """
        common: dict[str, Any] = {"tc4": scenario.tc4, "tc_noise": scenario.tc_noise, "seed": scenario.seed,
                                  "oscillation": scenario.oscillation, "faults": scenario.faults,
                                  "other_tc4": other_tc4}
        if scenario.truth == "shared":
            return cls(cfg, radiation, mismatch=scenario.mismatch, **common)
        truth = Truth.of(cfg, truth_radiation)
        return cls(cfg, truth.radiation, mismatch=deviations(cfg, scenario.mismatch), truth=truth, **common)

    # ---- the Furnace protocol
    @property
    def t_s(self) -> float:
        return float(self.cfg.sampling.t_s)

    @property
    def tc_positions(self) -> Array:
        return self.thermocouples.positions

    @property
    def time(self) -> float:
        """The plant's current time (s): the next sample to read."""
        return self._state.t

    def _check_time(self, t: float, what: str) -> None:
        if abs(t - self._state.t) > 1e-9 * max(1.0, abs(t)):
            raise ValueError(f"{what} at t = {t:.6g} s, but the simulated furnace is at t = {self._state.t:.6g} s")

    def read(self, t: float) -> Readings:
        """TC1..TC4 at the plant's current time t: bilinear in the field (lagged and biased with a truth) plus
        N(0, tc_noise^2) (section 3.2), as the injected faults leave them.

        Reading the same sample again returns the same readings (no new noise draw)."""
        self._check_time(t, "read")
        if self._last_read is not None and self._last_read[0] == self._state.t:
            return self._last_read[1]
        T = self._state.T
        clean = self.thermocouples.true_values(T) if self._sensors is None else self._sensors.values()
        # one draw for TC1..TC4; the other TC4 places take TC4's, as TC4 there would have had it in its own run
        draw = self._rng.standard_normal(clean.shape) if self._tc_noise > 0.0 else None
        readings = self._readings(t, clean, draw, self.faults)
        others = tuple(self._readings(t, o.clean(T), draw, o.faults) for o in self._others)
        self._last_read = (self._state.t, readings, others)
        return readings

    def _readings(self, t: float, clean: Array, draw: Array | None, faults: FaultInjector) -> Readings:
        values = clean if draw is None else clean + self._tc_noise * draw
        values, status = faults.readings(t, values)
        return Readings(values=values, timestamps=np.full(len(values), float(t)), status=status)

    def other_tc4_readings(self, t: float) -> tuple[Readings, ...]:
        """TC1..TC4 of sample t with TC4 at each ``other_tc4`` place (TC1..TC3 as :meth:`read`): what a run of
        this furnace with TC4 there reads (the same noise draw, bias, lag and injected faults as TC4's)."""
        self.read(t)
        assert self._last_read is not None
        return self._last_read[2]

    def apply(self, u: Array, t: float) -> None:
        """Hold u over [t, t + t_s]: the plant moves on by one sample (inputs clipped to [0, 1]; a failed or
        derated lamp group delivers less).

        With a truth the lamps radiate the lagged power (its mean over the sample, held by the plant)
        and the thermocouples follow the plate with their lag."""
        self._check_time(t, "apply")
        delivered = self.faults.delivered(t, u)  # a failed group's lamps go dark with their own lag
        power = delivered if self._lamps is None else self._lamps.step(delivered, self.t_s)
        self._state = self.plant.advance(self._state, power, self.t_s, self._eta_of_t)
        if self._sensors is not None:
            self._sensors.advance(self._state.T, self.t_s)
        for other in self._others:
            other.advance(self._state.T, self.t_s)

    # ---- fault injection (twin.furnace.interface.FaultInjectable)
    def set_faults(self, faults: Sequence[FaultSpec], t: float) -> None:
        """Replace the injected faults from run time t on (their ``at`` counted from t; empty clears them); a
        reading of the current sample taken before is read again with them."""
        for injector in (self.faults, *(o.faults for o in self._others)):
            injector.schedule(faults, t)
        self._last_read = None

    def faults_in_force(self) -> list[FaultSpec]:
        return self.faults.in_force()

    def take_fault_events(self) -> list[str]:
        return self.faults.take_events()

    def motion(self, t: float) -> Motion:
        return Motion(eta=float(self._eta_of_t(t)), oscillation=self._oscillation, since=self._since)

    def set_oscillation(self, spec: OscillationSpec, t: float) -> None:
        """New drive settings from t: eta restarts at 0 (the integrator restarts with it)."""
        self._oscillation, self._since = spec, float(t)
        self._eta_of_t = eta_function(spec, t0=float(t))
        self._state = self._state.restarted()

    def true_field(self) -> Array:
        return self._state.T.copy()

    def lamps_off_means(self, mean: Callable[[Array], float], n: int) -> Array:
        """``mean`` of the true field (e.g. ``Fillet.mean``) at the samples 0 .. n-1 of this furnace left with every
        lamp off from its start: its own truth, start and initial motion, a plant of its own (the run's is not
        touched).  Lamp power only adds heat, so under any input the true field's fillet mean is at least this:
        the reference's lead over it bounds every controller's transient error from below
        (``true_mean_lead_lamps_off_max``, :mod:`twin.runs.metrics`)."""
        state, off = self.plant.start(self._T_init.copy(), 0.0), np.zeros(self.cfg.n_groups)
        out = np.empty(max(int(n), 0))
        for j in range(out.size):
            out[j] = mean(state.T)
            if j + 1 < out.size:
                state = self.plant.advance(state, off, self.t_s, self._eta_initial)
        return out

    def drain_events(self) -> tuple[str, ...]:
        return ()

    def close(self) -> None:
        return None


class _OtherTC4:
    """TC1..TC4 with TC4 at another place: its own interpolation rows, lag and bias (the run's seed: the same
    biases as the furnace's own TCs) and fault injector; the noise comes from the furnace's draw."""

    def __init__(self, cfg: FurnaceConfig, place: tuple[float, float], T0: Array, truth: Truth | None, seed: int,
                 faults: FaultInjector) -> None:
        self.thermocouples = Thermocouples(cfg, cfg.tc_positions(place))
        self.sensors = None if truth is None else LaggedThermocouples(
            self.thermocouples, T0, seed=seed, time_constant=truth.tc_time_constant, bias=truth.tc_bias)
        self.faults = FaultInjector(faults.groups, faults.faults)

    def clean(self, T: Array) -> Array:
        """The readings before noise and faults (K)."""
        return self.thermocouples.true_values(T) if self.sensors is None else self.sensors.values()

    def advance(self, T: Array, h: float) -> None:
        if self.sensors is not None:
            self.sensors.advance(T, h)
