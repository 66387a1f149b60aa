"""The simulated furnace: full-order FD plant (eqs. 1-6), thermocouples and specimen drive."""

from twin.furnace.simulated.furnace import SimulatedFurnace

__all__ = ["SimulatedFurnace"]
