"""Radiation in the furnace chamber: exchange factors F^s(eta) (ray tracing), the net-radiation
matrices P1(eta), P2(eta) of eqs. (4)-(5), and their disk cache."""

from twin.radiation.model import RadiationModel, radiation_model

__all__ = ["RadiationModel", "radiation_model"]
