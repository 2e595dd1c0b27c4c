"""The local lab: N agents on loopback started by `sdrpeer lab up` (up.py), its files and
teardown (files.py)."""
