"""How an instance spec becomes a host command: the launchers (launchers.py, a plugin registry)
and what an agent lets run (policy.py)."""
