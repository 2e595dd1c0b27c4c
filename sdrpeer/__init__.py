"""sdrpeer: a leaderless platform for software-defined robots."""

__version__ = "0.1.0"
