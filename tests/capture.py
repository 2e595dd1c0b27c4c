"""The packet capture (sdrpeer.netlab.capture) for tests, and the mark of tests that need it."""

from __future__ import annotations

import os

import pytest

from sdrpeer.netlab.capture import Capture

__all__ = ["ROOT_ONLY", "Capture"]

ROOT_ONLY = pytest.mark.skipif(
    os.geteuid() != 0, reason="PACKET CAPTURE NOT TESTED: a raw socket needs root"
)
"""Marks a test that captures packets."""
