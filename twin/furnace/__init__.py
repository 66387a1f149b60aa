"""The furnace side of the boundary: the :class:`Furnace` interface the loop talks to, and its implementations."""

from twin.furnace.interface import Furnace, Motion, Readings

__all__ = ["Furnace", "Motion", "Readings"]
