"""Design studies: grids and Monte Carlo samples of closed-loop runs on Dask (``furnace-twin study``).

spec (the study file), distributions, cases (expansion and keys), worker (one case on a Dask worker),
cluster (LocalCluster or a running scheduler), engine (run, store, resume), store (records and the results
table), timing, figures, report (``study.md``), command (the CLI).
"""
