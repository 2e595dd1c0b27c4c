"""A robot's gossip record: its codec (robot.py) and the ranges of every fact it carries
(limits.py)."""
