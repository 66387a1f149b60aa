"""The terms of the reduced model (eq. 12a) at every tabulated specimen position, split by physical origin.

Eq. (12a) with eq. (10) reads f(theta, u) = L theta + A (M_theta theta)^4 + B u + c.  Its terms
come from different physics, and the twin needs them apart:

* the position: the radiation terms A, B and the wall part of c depend on eta through P1(eta_n),
  P2(eta_n) (eq. 4); the time-averaged model (eq. 11) weights them with the period-average weights,
  a position-aware model with the hat weights at eta(t);
* the calibration parameters (relative deviations, like a scenario's ``mismatch``):

  - lamp efficiency p_L: B -> (1 + p_L) B, exact (u_max scales);
  - convection p_c: the face and edge losses (alpha_ig, alpha_h of eqs. 3, 6) -> (1 + p_c) x, exact;
  - specimen emissivity p_e: A, B and the wall term through the net-radiation method (eq. 5), linearised
    by a central difference of P1, P2 in eps: A -> A + p_e dA/dp_e (likewise B, c_wall).

So, with w the position weights,

    L(p) = L_cond + (1 + p_c) L_loss,     c(p, w) = (1 + p_c) c_loss + sum_n w_n (c_wall,n + p_e dc_n),
    A(p, w) = sum_n w_n (A_n + p_e dA_n), B(p, w) = (1 + p_L) sum_n w_n (B_n + p_e dB_n),

with L_cond = (rho M)^-1 K, L_loss = -(rho M)^-1 (Gamma + G^T diag(d) M_theta / B_s), c_loss =
(rho M)^-1 (gamma_0 + G^T b / B_s), A_n = -(rho M)^-1 G^T P1_n[:, :N_s] / B_s, B_n = -(rho M)^-1
G^T P2_n diag(u_max) G_lamps / B_s, c_wall,n = -(rho M)^-1 G^T P1_n[:, N_s:] T_w^4 / B_s.

Example
-------
>>> from twin.config import small_config
>>> from twin.radiation import radiation_model
>>> cfg = small_config()
>>> tables = model_tables(cfg, radiation_model(cfg))
>>> tables.A.shape[0] == len(tables.eta_nodes), tables.B.shape[1:]
(True, (105, 6))
"""

from __future__ import annotations

import logging
import threading
import weakref
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Protocol

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from twin.config import FurnaceConfig
from twin.model.fe import FEModel
from twin.physics.boundary import face_loss_coefficients

log = logging.getLogger(__name__)
Array = NDArray[np.float64]

#: Relative step of the central difference in the specimen emissivity (dA/dp_e etc.): the net
#: radiation is smooth in eps, and +-2 % keeps the truncation error ~1e-4 of the sensitivity.
EMISSIVITY_STEP = 0.02

PARAMETERS = ("lamp_efficiency", "emissivity", "convection")


class RadiationLike(Protocol):
    """The parts of :class:`twin.radiation.RadiationModel` the reduced model uses (docs/interfaces.md)."""

    @property
    def eta_nodes(self) -> Array: ...
    @property
    def P1(self) -> Array: ...
    @property
    def P2(self) -> Array: ...
    @property
    def wall_temperatures(self) -> Array: ...
    @property
    def lamp_flux_max(self) -> Array: ...


@dataclass(frozen=True)
class Parameters:
    """The calibration parameters as relative deviations from the nominal model (0.05 = 5 % higher)."""

    lamp_efficiency: float = 0.0
    emissivity: float = 0.0
    convection: float = 0.0

    def as_array(self) -> Array:
        return np.array([self.lamp_efficiency, self.emissivity, self.convection], float)

    @classmethod
    def from_array(cls, p: ArrayLike) -> Parameters:
        v = np.asarray(p, float)
        return cls(float(v[0]), float(v[1]), float(v[2]))


@dataclass(frozen=True, eq=False)
class ModelTables:
    """The pieces of eq. (12a) per position eta_n (see the module docstring).

    Attributes
    ----------
    fe : the FE discretisation;  t_s : s;  eta_nodes : (n_eta,) m
    L_cond, L_loss : (n, n) 1/s;  c_loss : (n,) K/s
    A : (n_eta, n, N_s) 1/(s K^3);  B : (n_eta, n, m) K/s;  c_wall : (n_eta, n) K/s
    """

    fe: FEModel
    t_s: float
    eta_nodes: Array
    L_cond: Array
    L_loss: Array
    c_loss: Array
    A: Array
    B: Array
    c_wall: Array
    _radiation: Any
    _cfg: FurnaceConfig

    @property
    def n(self) -> int:
        return self.fe.n

    @property
    def m(self) -> int:
        return int(self.B.shape[2])

    @cached_property
    def emissivity_sensitivity(self) -> tuple[Array, Array, Array]:
        """(dA, dB, dc_wall) per unit relative emissivity deviation, by a central difference of eq. (5)."""
        eps, cfg, rad = self._cfg.specimen.emissivity, self._cfg, self._radiation
        plus = _radiation_terms(cfg, self.fe, rad.with_specimen_emissivity(eps * (1 + EMISSIVITY_STEP)))
        minus = _radiation_terms(cfg, self.fe, rad.with_specimen_emissivity(eps * (1 - EMISSIVITY_STEP)))
        h = 2.0 * EMISSIVITY_STEP
        return tuple((p - m) / h for p, m in zip(plus, minus, strict=True))  # type: ignore[return-value]

    def terms(self, weights: ArrayLike, p: Parameters | None = None) -> tuple[Array, Array, Array, Array]:
        """L, A, B, c of eq. (12a) for position weights w (n_eta,) and parameters p (module docstring)."""
        w = np.asarray(weights, float)
        pv = p or Parameters()
        A = np.tensordot(w, self.A, axes=1)
        B = np.tensordot(w, self.B, axes=1)
        c_wall = w @ self.c_wall
        if pv.emissivity != 0.0:
            dA, dB, dc = self.emissivity_sensitivity
            A = A + pv.emissivity * np.tensordot(w, dA, axes=1)
            B = B + pv.emissivity * np.tensordot(w, dB, axes=1)
            c_wall = c_wall + pv.emissivity * (w @ dc)
        scale = 1.0 + pv.convection
        return (self.L_cond + scale * self.L_loss, A, (1.0 + pv.lamp_efficiency) * B, scale * self.c_loss + c_wall)


def _lu(cfg: FurnaceConfig, fe: FEModel) -> Any:
    return scipy.linalg.lu_factor(cfg.specimen.density * fe.M)


def _radiation_terms(cfg: FurnaceConfig, fe: FEModel, radiation: RadiationLike) -> tuple[Array, Array, Array]:
    """A_n (n_eta, n, N_s), B_n (n_eta, n, m), c_wall,n (n_eta, n) of a radiation model's tables."""
    s = cfg.specimen
    Ns, Bs = s.n_states, s.thickness
    lu = _lu(cfg, fe)
    P1 = np.asarray(radiation.P1, float)
    P2 = np.asarray(radiation.P2, float)
    Tw4 = np.asarray(radiation.wall_temperatures, float) ** 4
    lamp = np.asarray(radiation.lamp_flux_max, float)[:, None] * np.asarray(cfg.group_matrix, float)
    GT = fe.G.T
    A = np.stack([scipy.linalg.lu_solve(lu, -GT @ P1[k, :, :Ns] / Bs) for k in range(len(P1))])
    B = np.stack([scipy.linalg.lu_solve(lu, -GT @ (P2[k] @ lamp) / Bs) for k in range(len(P2))])
    c = np.stack([scipy.linalg.lu_solve(lu, -GT @ (P1[k, :, Ns:] @ Tw4) / Bs) for k in range(len(P1))])
    return A, B, c


#: tables already built, per radiation model (weakly held) and furnace config: every run of a server or a
#: campaign shares them (and the emissivity sensitivity, once computed), as it shares the radiation model
_TABLES: weakref.WeakKeyDictionary[Any, dict[str, ModelTables]] = weakref.WeakKeyDictionary()
_TABLES_LOCK = threading.Lock()


def model_tables(cfg: FurnaceConfig, radiation: RadiationLike, fe: FEModel | None = None) -> ModelTables:
    """The per-position terms of eq. (12a) for the FE model of ``cfg`` and a radiation model's tables.

    Cached per radiation model and config (unless a prebuilt ``fe`` is given): they are immutable.
    """
    if fe is None:
        try:
            with _TABLES_LOCK:
                hit = _TABLES.get(radiation, {}).get(cfg.digest())
        except TypeError:  # not weakly referenceable (a test's stand-in): no cache
            hit = None
        if hit is not None:
            return hit
        tables = _build(cfg, radiation, FEModel(cfg))
        try:
            with _TABLES_LOCK:
                _TABLES.setdefault(radiation, {})[cfg.digest()] = tables
        except TypeError:
            pass
        return tables
    return _build(cfg, radiation, fe)


def _build(cfg: FurnaceConfig, radiation: RadiationLike, fe: FEModel) -> ModelTables:
    s = cfg.specimen
    d, b = face_loss_coefficients(cfg)
    G, Mt, Bs = fe.G, fe.M_theta, s.thickness
    lu = _lu(cfg, fe)
    L_cond = scipy.linalg.lu_solve(lu, fe.K)
    L_loss = scipy.linalg.lu_solve(lu, -fe.Gamma - G.T @ (d[:, None] * Mt) / Bs)
    c_loss = scipy.linalg.lu_solve(lu, fe.gamma0 + G.T @ b / Bs)
    A, B, c_wall = _radiation_terms(cfg, fe, radiation)
    log.debug("model_tables: n=%d, %d positions", fe.n, len(A))
    return ModelTables(fe=fe, t_s=cfg.sampling.t_s, eta_nodes=np.asarray(radiation.eta_nodes, float),
                       L_cond=L_cond, L_loss=L_loss, c_loss=c_loss, A=A, B=B, c_wall=c_wall,
                       _radiation=radiation, _cfg=cfg)
