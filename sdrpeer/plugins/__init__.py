"""Plugins: one registry (registry.py) for every kind a package can add through an entry point
group: launchers, allocation strategies and constraints, recovery conditions and actions."""
