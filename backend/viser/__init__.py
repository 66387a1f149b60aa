"""The viser 3D view: scene drawing (``scene``), the GUI panel (``controls``), a finished run's last
sample (``stored``) and the view that follows runs through the run manager (``view``)."""

from backend.viser.controls import AUTO, Controls, build_controls
from backend.viser.scene import (
    LAMP_OFF,
    LAMP_ON,
    MIN_SPAN_K,
    FurnaceScene,
    colour_range,
    lamp_colors,
    plate_mesh,
    turbo_rgb,
    vertex_values,
)
from backend.viser.stored import StoredSnapshot, stored_snapshot
from backend.viser.view import FurnaceView

__all__ = [
    "AUTO", "LAMP_OFF", "LAMP_ON", "MIN_SPAN_K", "Controls", "FurnaceScene", "FurnaceView", "StoredSnapshot",
    "build_controls", "colour_range", "lamp_colors", "plate_mesh", "stored_snapshot", "turbo_rgb", "vertex_values",
]
