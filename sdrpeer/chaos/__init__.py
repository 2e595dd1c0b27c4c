"""The chaos soak: seeded faults on a lab while invariants are checked all the time."""
