"""The agent's HTTP API: JSON under /v1, Prometheus text at /metrics."""
