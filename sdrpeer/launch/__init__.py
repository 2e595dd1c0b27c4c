"""How an instance spec becomes a host command: the launchers (launchers.py, a plugin registry),
what an agent lets run (policy.py) and whether OpenRTM is here for the openrtm launcher
(openrtm.py)."""
