"""The browser tests' gate: Chromium and Playwright must be there, or the tests say so loudly.

`chromium_or_fail()` returns the browser's path; when it or the Playwright package is missing the
test fails saying what to install, unless SDRPEER_SKIP_BROWSER is set, in which case it is skipped
with that reason (never a silent pass). `tools/check` installs both where it can (as root).
"""

from __future__ import annotations

import os

import pytest

from sdrpeer.dashboard.chromium import find_chromium, have_playwright


def chromium_or_fail() -> str:
    """The browser's path; fails (or skips, with SDRPEER_SKIP_BROWSER) when it cannot run."""
    missing = []
    path = find_chromium()
    if path is None:
        missing.append("Chromium (apt-get install chromium)")
    if not have_playwright():
        missing.append("Playwright (pip install playwright)")
    if missing:
        text = f"BROWSER TESTS NOT RUN: {' and '.join(missing)} not installed"
        if os.environ.get("SDRPEER_SKIP_BROWSER"):
            pytest.skip(text + " (SDRPEER_SKIP_BROWSER is set)")
        pytest.fail(text + "; install them, or set SDRPEER_SKIP_BROWSER=1 to skip these tests")
    assert path is not None
    return path
