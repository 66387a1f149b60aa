"""The plant's energy bookkeeping: stored energy and the power balance of the whole plate (eqs. 1-6).

    dE/dt = absorbed - emitted - convective - holder,      E = rho B_s A sum_k h(T_k),

with h the specific enthalpy of the steel (integral of c_p), so a run's energy change can be
checked against the time integral of the power terms.

Example
-------
>>> import numpy as np
>>> from twin.config import small_config
>>> from twin.furnace.simulated.plant import Plant
>>> plant = Plant(small_config(), radiation=None)
>>> p = power_balance(plant, np.full(plant.n, 900.0), np.zeros(6), 0.0)
>>> p["absorbed"], p["convective"] > 0, p["holder"] > 0
(0.0, True, True)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from twin.furnace.simulated.plant import Plant


def stored_energy(plant: Plant, T: ArrayLike) -> float:
    """Energy content rho B_s A sum_k h(T_k) in J (h from the first table temperature)."""
    return float(plant.capacity_factor * np.sum(plant.steel.enthalpy(np.asarray(T, float))))


def power_balance(
    plant: Plant, T: ArrayLike, u: ArrayLike | None, eta: float, *, u_lamps: ArrayLike | None = None
) -> dict[str, float]:
    """Power balance of the whole plate in W; dE/dt = absorbed - emitted - convective - holder.

    Keys: ``absorbed`` (lamp radiation absorbed, -A sum P2 u_lamp), ``emitted`` (net thermal
    radiation leaving, A sum P1 [T^4; T_w^4]), ``convective`` (inert gas on the faces, eq. 6,
    and through the side edges, 3c-d), ``holder`` (jaw contact, eq. 6, and the end edges,
    3a-b), ``conduction_interior`` (sum of interior face flows, zero up to rounding).
    """
    Tv = np.asarray(T, float)
    v1, per_lamp = plant.inputs(u, u_lamps)
    A = plant.area
    absorbed = emitted = 0.0
    if plant.source is not None:
        absorbed = -A * float(np.sum(plant.source.lamp_flux(v1[:-1], per_lamp, eta)))
        emitted = A * float(np.sum(plant.source.flux(Tv, v1, per_lamp, eta))) + absorbed
    edges = plant.conduction.edge_losses(Tv)
    interior = float(np.sum(plant.conduction.heat_flow(Tv))) + edges["holder_edges"] + edges["gas_edges"]
    return {
        "absorbed": absorbed,
        "emitted": emitted,
        "convective": A * float(np.sum(plant.h_gas * (Tv - plant.T_gas))) + edges["gas_edges"],
        "holder": A * float(np.sum(plant.h_holder * (Tv - plant.T_holder))) + edges["holder_edges"],
        "conduction_interior": interior,
    }
