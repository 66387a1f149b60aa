"""The reduced model as the estimator runs it: at the specimen's position, with calibration parameters.

    theta_{j+1} = F(theta_j, u_j; w(eta_j), p) = theta_j + t_s f(theta_j, u_j; w, p)          (12a)

with the terms of :mod:`twin.model.tables`.  The position enters through the weights w of the
tabulated positions:

* ``motion="averaged"``: the period-average weights of eq. (11) (constant during an
  oscillation; the paper's model, and the one the controller uses);
* ``motion="position_aware"``: the hat weights at the known position eta(t_j) (section 5.2 names
  the averaged model as the cause of its 3 % TC4 error and suggests this).  For a fixed specimen
  both are the weights at eta = 0, so both models are the same.

With ``cfg.fe.heat_capacity = "temperature"`` the model's heat capacity follows the steel's table
(the Curie peak; the paper's remark in section 2.2) instead of the constant enthalpy-equivalent c_p
of M: lumped at the nodes, f -> D(theta) f with D_i = c_bar / c_p(theta_i).

The parameters p (relative deviations of lamp efficiency, emissivity, convection; see
:class:`twin.model.tables.Parameters`) enter linearly, so F and its Jacobians in theta (eq. 16) and
in p are cheap: the per-position terms are blended for the (at most two) nodes with non-zero weight.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.model.tables import model_tables
>>> from twin.radiation import radiation_model
>>> from twin.scenario import OscillationSpec
>>> cfg = small_config()
>>> tables = model_tables(cfg, radiation_model(cfg))
>>> osc = OscillationSpec(enabled=True, amplitude=0.02, period=4.0)
>>> aware = ParametricModel(tables, osc, motion="position_aware")
>>> theta = np.full(tables.n, 900.0)
>>> a, b = aware.step(theta, np.full(6, 0.5), 0.02), aware.step(theta, np.full(6, 0.5), -0.02)
>>> bool(np.abs(a - b).max() > 1e-6)    # the model knows where the plate is
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse
from numpy.typing import ArrayLike, NDArray

from twin.model.tables import PARAMETERS, ModelTables, Parameters
from twin.physics.materials import Steel
from twin.physics.motion import average_weights, hat_interval
from twin.scenario import OscillationSpec

Array = NDArray[np.float64]
Motion = Literal["averaged", "position_aware"]


@dataclass(frozen=True, eq=False)
class Evaluation:
    """f of eq. (12a) at one (theta, u, eta, p) with its parts: the constant-capacity f (K/s), the cell
    field T (K), and the derivatives of f in the parameters: ``loss`` (d f / d p_c), ``lamps``
    (d f / d p_L), ``emission`` (d f / d p_e, None unless the emissivity is calibrated); ``capacity``
    the (D, dD/dtheta) of a temperature-dependent heat capacity, else None."""

    theta: Array
    T: Array
    f: Array
    loss: Array
    lamps: Array
    emission: Array | None
    capacity: tuple[Array, Array] | None

    @property
    def rate(self) -> Array:
        """d theta / dt (K/s): f, scaled by D with a temperature-dependent heat capacity."""
        return self.f if self.capacity is None else self.capacity[0] * self.f


@dataclass(frozen=True, eq=False)
class _Node:
    """The radiation terms of one position (a table node, or the period average).

    With the emissivity calibrated, ``AdA`` = [A; dA] (2n, N_s) and ``BdB`` = [B; dB] (2n, m) stacked, so
    one product gives both (the products stream the matrices from memory once).
    """

    A: Array  # (n, N_s)
    B: Array  # (n, m)
    c_wall: Array  # (n,)
    dA: Array | None  # emissivity sensitivities (None when emissivity is not calibrated)
    dB: Array | None
    dc: Array | None
    AdA: Array | None = None
    BdB: Array | None = None


class ParametricModel:
    """F(theta, u; eta, p) of eq. (12a) with the position handled by ``motion`` (module docstring).

    Parameters
    ----------
    tables : the per-position terms
    oscillation : the motion the averaged weights belong to (None or disabled: fixed at eta = 0)
    motion : "averaged" or "position_aware"
    calibrated : names of the parameters the estimator learns (subset of ``PARAMETERS``); only those
        get Jacobian columns in :meth:`jac_p`
    """

    def __init__(self, tables: ModelTables, oscillation: OscillationSpec | None, *,
                 motion: Motion = "averaged", calibrated: tuple[str, ...] = (),
                 heat_capacity: Literal["constant", "temperature"] = "constant") -> None:
        unknown = set(calibrated) - set(PARAMETERS)
        if unknown:
            raise ValueError(f"unknown calibration parameters {sorted(unknown)}; known: {PARAMETERS}")
        self.tables = tables
        self.fe = tables.fe
        self.t_s = tables.t_s
        self.oscillation = oscillation
        self.motion: Motion = motion
        self.calibrated = tuple(p for p in PARAMETERS if p in calibrated)
        self._eta_list = [float(v) for v in tables.eta_nodes]
        self._with_emissivity = "emissivity" in self.calibrated
        self._nodes: dict[int, _Node] = {}
        self._average = self._node_of(average_weights(tables.eta_nodes, oscillation))
        self._mt_sparse = scipy.sparse.csr_matrix(self.fe.M_theta.T)
        self.heat_capacity = heat_capacity
        self._steel = Steel.from_config(tables.fe.cfg) if heat_capacity == "temperature" else None

    def capacity_scaling(self, theta: Array) -> tuple[Array, Array] | None:
        """D_i = c_bar / c_p(theta_i) and dD_i / dtheta_i (1/K) with a temperature-dependent c_p, else None."""
        if self._steel is None:
            return None
        cp = self._steel.heat_capacity(theta)
        c_bar = self.fe.heat_capacity
        return c_bar / cp, -c_bar * self._steel.heat_capacity_slope(theta) / cp**2

    def with_oscillation(self, oscillation: OscillationSpec | None) -> ParametricModel:
        """The same model for another motion (after a live switch); the per-position terms are shared."""
        other = ParametricModel.__new__(ParametricModel)
        other.__dict__.update(self.__dict__)
        other.oscillation = oscillation
        other._average = self._node_of(average_weights(self.tables.eta_nodes, oscillation))
        return other

    @property
    def A(self) -> Array:
        """The radiation term A of eq. (12a) with the period-average weights (eq. 11), nominal parameters."""
        return self._average.A

    @property
    def B(self) -> Array:
        """The input matrix B of eq. (12a) with the period-average weights (eq. 11), nominal parameters."""
        return self._average.B

    @property
    def n(self) -> int:
        return self.tables.n

    @property
    def m(self) -> int:
        return self.tables.m

    @property
    def c_m(self) -> Array:
        return self.fe.c_m

    def _node_of(self, w: Array) -> _Node:
        t = self.tables
        A = np.tensordot(w, t.A, axes=1)
        B = np.tensordot(w, t.B, axes=1)
        c = w @ t.c_wall
        if not self._with_emissivity:
            return _Node(np.ascontiguousarray(A), B, c, None, None, None)
        dA, dB, dc = t.emissivity_sensitivity
        dA_w, dB_w = np.tensordot(w, dA, axes=1), np.tensordot(w, dB, axes=1)
        return _Node(np.ascontiguousarray(A), B, c, dA_w, dB_w, w @ dc,
                     np.ascontiguousarray(np.vstack([A, dA_w])), np.ascontiguousarray(np.vstack([B, dB_w])))

    def _table_node(self, k: int) -> _Node:
        node = self._nodes.get(k)
        if node is None:
            w = np.zeros(len(self._eta_list))
            w[k] = 1.0
            node = self._nodes[k] = self._node_of(w)
        return node

    def positions(self, eta: float) -> list[tuple[_Node, float]]:
        """The nodes with non-zero weight at eta, and their weights (the period average when averaged)."""
        if self.motion == "averaged":
            return [(self._average, 1.0)]
        k, w = hat_interval(self._eta_list, float(eta))
        out = [(self._table_node(k), 1.0 - w)]
        if w > 0.0:
            out.append((self._table_node(k + 1), w))
        return out

    def evaluate(self, theta: ArrayLike, u: ArrayLike, eta: float = 0.0, p: Parameters | None = None) -> Evaluation:
        """Everything one sample needs, computed once: f, its parts by parameter, the cell field."""
        th = np.asarray(theta, float)
        uv = np.asarray(u, float)
        pv = p or Parameters()
        t = self.tables
        T = self.fe.field_on_cells(th).ravel()
        T4 = (T * T) ** 2
        loss = t.L_loss @ th + t.c_loss
        f = t.L_cond @ th + (1.0 + pv.convection) * loss
        gain = 1.0 + pv.lamp_efficiency
        lamps = np.zeros(self.n)  # sum_w (B + p_e dB) u: d f / d p_L
        emission = np.zeros(self.n) if self._with_emissivity else None  # d f / d p_e
        n = self.n
        for node, w in self.positions(eta):
            if node.AdA is not None and node.BdB is not None and node.dc is not None and emission is not None:
                AT4, BU = node.AdA @ T4, node.BdB @ uv
                d = AT4[n:] + node.dc
                Bu = BU[:n] + pv.emissivity * BU[n:]
                r = AT4[:n] + node.c_wall + pv.emissivity * d
                emission += w * (d + gain * BU[n:])
            else:
                Bu = node.B @ uv
                r = node.A @ T4 + node.c_wall
            lamps += w * Bu
            f += w * r
        f += gain * lamps
        return Evaluation(theta=th, T=T, f=f, loss=loss, lamps=lamps, emission=emission,
                          capacity=self.capacity_scaling(th))

    def input_matrix(self, eta: float = 0.0, p: Parameters | None = None) -> Array:
        """d f / d u (n, m) in K/s at the position's weights: (1 + p_L) sum_w (B + p_e dB), constant capacity."""
        pv = p or Parameters()
        out = np.zeros((self.n, self.m))
        for node, w in self.positions(eta):
            B = node.B if node.dB is None else node.B + pv.emissivity * node.dB
            out += w * B
        return (1.0 + pv.lamp_efficiency) * out

    def rhs(self, theta: ArrayLike, u: ArrayLike, eta: float = 0.0, p: Parameters | None = None) -> Array:
        """f(theta, u; eta, p) in K/s (with the temperature-dependent capacity if configured)."""
        return self.evaluate(theta, u, eta, p).rate

    def step(self, theta: ArrayLike, u: ArrayLike, eta: float = 0.0, p: Parameters | None = None) -> Array:
        """F(theta, u; eta, p) = theta + t_s f (eq. 12a)."""
        e = self.evaluate(theta, u, eta, p)
        return e.theta + self.t_s * e.rate

    def radiation_jacobian(self, node: _Node, T: Array, emissivity: float = 0.0) -> Array:
        """t_s (A + p_e dA) diag(4 T^3) M_theta of one position (n, n): the radiation part of eq. (16)."""
        A = node.A if emissivity == 0.0 or node.dA is None else node.A + emissivity * node.dA
        scaled = A.T * (4.0 * self.t_s * T**3)[:, None]  # (N_s, n)
        return np.asarray((self._mt_sparse @ scaled).T)

    def linear_jacobian(self, p: Parameters | None = None) -> Array:
        """I + t_s L(p): the part of eq. (16) that depends neither on theta nor on the position."""
        pv = p or Parameters()
        t = self.tables
        return np.eye(self.n) + self.t_s * (t.L_cond + (1.0 + pv.convection) * t.L_loss)

    def jac_theta(self, theta: ArrayLike, u: ArrayLike | None = None, eta: float = 0.0,
                  p: Parameters | None = None) -> Array:
        """dF/dtheta (n, n), eq. (16), at the position's weights (exact, no caching)."""
        pv = p or Parameters()
        e = self.evaluate(theta, np.zeros(self.m) if u is None else u, eta, pv)
        J = self.linear_jacobian(pv)
        for node, w in self.positions(eta):
            J += w * self.radiation_jacobian(node, e.T, pv.emissivity)
        return self.with_capacity(J, e)

    def with_capacity(self, J: Array, e: Evaluation) -> Array:
        """Phi of the constant-capacity model -> Phi with c_p(theta): I + D (Phi - I) + t_s diag(f dD/dtheta)."""
        if e.capacity is None:
            return J
        D, dD = e.capacity
        out = D[:, None] * J
        out[np.diag_indices(self.n)] += (1.0 - D) + self.t_s * e.f * dD
        return np.asarray(out)

    def jac_p(self, theta: ArrayLike, u: ArrayLike, eta: float = 0.0, p: Parameters | None = None) -> Array:
        """dF/dp (n, len(calibrated)) for the calibrated parameters, in K per unit relative deviation."""
        return self.jac_p_of(self.evaluate(theta, u, eta, p))

    def jac_p_of(self, e: Evaluation) -> Array:
        """dF/dp from an :meth:`evaluate` result (the predict step shares it with F and Phi)."""
        if not self.calibrated:
            return np.zeros((self.n, 0))
        parts = {"lamp_efficiency": e.lamps, "convection": e.loss, "emissivity": e.emission}
        cols = []
        for name in self.calibrated:
            col = parts[name]
            assert col is not None  # the emission part exists when the emissivity is calibrated
            cols.append(col)
        Jp = self.t_s * np.column_stack(cols)
        return Jp if e.capacity is None else e.capacity[0][:, None] * Jp
