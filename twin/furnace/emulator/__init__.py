"""``furnace-twin emulate``: a simulated furnace served in real time as an OPC UA server (hardware in the loop).

``interlock`` (setpoint clamps, the watchdog), ``address_space`` (the nodes), ``timing`` (jitter and latency
figures), ``server`` (:class:`FurnaceEmulator`, the real-time ticks) and ``command`` (the CLI).
"""
