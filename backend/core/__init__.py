"""What every part of the server shares: settings, security, error bodies and plain messages, a threaded server."""
