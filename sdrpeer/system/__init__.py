"""System files: what a fleet should run (components, connections, allocation, recovery)."""
