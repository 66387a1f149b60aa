"""Design studies in the server: queued and run one at a time (``manager``)."""
