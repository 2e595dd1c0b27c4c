"""The `sdrpeer` command (placeholder until the CLI lands)."""

from __future__ import annotations


def main() -> int:
    """Entry point."""
    return 0
