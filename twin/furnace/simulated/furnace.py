"""The simulated furnace: the full-order plant, its thermocouples and the specimen drive behind the
furnace boundary (:class:`twin.furnace.interface.Furnace`).

It is the "truth" of a simulated run: the plant (eqs. 1-6) with its own radiation tables and
deviations from the model (``mismatch``), Gaussian TC noise from the run's seed, and eta(t) of
the oscillation in force.  Time advances only through :meth:`SimulatedFurnace.apply`: each call
integrates the plant over one sample with the powers held, so samples are read and applied in
order (t_j, t_j + t_s, ...).

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
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.furnace.interface import Motion, Readings
from twin.furnace.simulated.plant import Plant
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.physics.motion import eta_function
from twin.scenario import Mismatch, OscillationSpec, Scenario

log = logging.getLogger(__name__)

Array = NDArray[np.float64]


class SimulatedFurnace:
    """Plant + thermocouples + specimen drive, the :class:`twin.furnace.interface.Furnace` of a simulation.

    Parameters
    ----------
    cfg : the furnace
    radiation : the plant's radiation model (``None``: no radiation, for tests)
    mismatch : the plant's relative deviations from the nominal model
    tc4 : relative position (x / L_s, y / W_s) of the validation thermocouple TC4
    tc_noise : TC noise standard deviation (K)
    seed : of the TC noise
    oscillation : the drive's settings at t = 0
    T0 : initial cell temperatures (K); default the configured uniform initial temperature
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
    ) -> None:
        self.cfg = cfg
        self.plant = Plant(cfg, radiation, mismatch)
        positions: Sequence[tuple[float, float]] = cfg.tc_positions(tc4)
        self.thermocouples = Thermocouples(cfg, positions)
        self._tc_noise = float(tc_noise)
        self._rng = np.random.default_rng(seed)
        T_init = np.full(self.plant.n, cfg.specimen.initial_temperature) if T0 is None else T0
        self._state = self.plant.start(T_init, 0.0)
        self._oscillation = oscillation or OscillationSpec()
        self._since = 0.0
        self._eta_of_t = eta_function(self._oscillation)
        self._last_read: tuple[float, Readings] | None = None  # (plant time, readings): a repeated read of
        # the same sample gives the same readings

    @classmethod
    def for_scenario(cls, cfg: FurnaceConfig, scenario: Scenario, radiation: Any) -> SimulatedFurnace:
        """The furnace of a scenario: its mismatch, TC4, TC noise, seed and initial oscillation."""
        return cls(cfg, radiation, mismatch=scenario.mismatch, tc4=scenario.tc4, tc_noise=scenario.tc_noise,
                   seed=scenario.seed, oscillation=scenario.oscillation)

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
        """TC1..TC4 at the plant's current time t: bilinear in the field plus N(0, tc_noise^2) (section 3.2).

        Reading the same sample again returns the same readings (no new noise draw)."""
        self._check_time(t, "read")
        if self._last_read is not None and self._last_read[0] == self._state.t:
            return self._last_read[1]
        values = self.thermocouples.read(self._state.T, self._rng, self._tc_noise)
        readings = Readings(values=values, timestamps=np.full(len(values), float(t)),
                            status=tuple("good" for _ in values))
        self._last_read = (self._state.t, readings)
        return readings

    def apply(self, u: Array, t: float) -> None:
        """Hold u over [t, t + t_s]: the plant moves on by one sample (inputs clipped to [0, 1])."""
        self._check_time(t, "apply")
        self._state = self.plant.advance(self._state, u, self.t_s, self._eta_of_t)

    def motion(self, t: float) -> Motion:
        return Motion(eta=float(self._eta_of_t(t)), oscillation=self._oscillation, since=self._since)

    def set_oscillation(self, spec: OscillationSpec, t: float) -> None:
        """New drive settings from t: eta restarts at 0 (the integrator restarts with it)."""
        self._oscillation, self._since = spec, float(t)
        self._eta_of_t = eta_function(spec, t0=float(t))
        self._state = self._state.restarted()

    def true_field(self) -> Array:
        return self._state.T.copy()

    def drain_events(self) -> tuple[str, ...]:
        return ()

    def close(self) -> None:
        return None
