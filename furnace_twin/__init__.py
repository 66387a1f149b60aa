"""The ``furnace-twin`` command line (``cli``): the composition root above ``twin``, ``backend`` and ``benchmarks``."""
