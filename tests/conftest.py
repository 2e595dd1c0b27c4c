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


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The tests that take 30 s or more by design (`slow`) go first: run side by side
    (`tools/check` runs pytest-xdist workers), a long test started last would end the run alone."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
