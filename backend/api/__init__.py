"""The REST API: one router per resource (``routes``), typed dependencies (``deps``), response schemas."""
