"""What stays on disk: the runs database, run folders, recordings, the data directory's quota, and recovery
after a crash."""
