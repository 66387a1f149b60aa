"""One router per resource: health (and the furnace description), runs, run files, run stream."""
