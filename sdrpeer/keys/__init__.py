"""Secrets: cluster keys for gossip (keyring.py) and the data keys hosts authenticate their data
connections with (datakeys.py)."""
