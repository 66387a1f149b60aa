"""``python -m furnace_twin`` is ``furnace-twin``."""

from furnace_twin.cli import main

raise SystemExit(main())
