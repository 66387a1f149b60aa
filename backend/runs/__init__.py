"""Hosting runs: the run manager, each run's task and worker thread, its change queue and checks, the loop
factory and the process a run steps in."""
