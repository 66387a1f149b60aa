"""The third-party furnace's own namespace, as o6 declares one (a module it publishes: furnace.py).  Imported by
the peer's process only (it imports o6, which ends its process after ten minutes)."""

import o6

o6.ns.namespace("lab", uri="urn:lab:annealer")
