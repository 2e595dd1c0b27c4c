"""Fixtures shared by more than one test module."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.realnet import RealCluster


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[RealCluster]:
    """Real agent processes on loopback, all killed at teardown."""
    net = RealCluster(tmp_path / "net")
    try:
        yield net
    finally:
        net.close()
