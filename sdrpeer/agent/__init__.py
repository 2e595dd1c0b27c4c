"""The agent of one robot: wiring (agent.py), its process entry (main.py), its files, views, key
rotation and logging. Nothing below this package imports it."""
