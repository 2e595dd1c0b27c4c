"""Headless Chromium for the dashboard's browser test and benchmark (tests/, tools/; the agent does
not use it): Debian's chromium driven by Playwright with `executable_path` (browsers cannot be
downloaded here).

`find_chromium()` finds the binary ($SDRPEER_CHROMIUM, else Debian's); `chromium_page()` opens a
fresh page whose console errors and page errors are collected in `page.errors`.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

CANDIDATES = ("/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome")
FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def find_chromium() -> str | None:
    """The Chromium binary ($SDRPEER_CHROMIUM, else Debian's), or None."""
    env = os.environ.get("SDRPEER_CHROMIUM")
    if env:
        return env if os.access(env, os.X_OK) else None
    for path in CANDIDATES:
        if os.access(path, os.X_OK):
            return path
    return shutil.which("chromium")


def have_playwright() -> bool:
    """Whether the Playwright package can be imported."""
    try:
        import playwright.sync_api  # noqa: F401, PLC0415 - optional
    except ImportError:
        return False
    return True


@contextmanager
def chromium_page(executable: str, width: int = 1400, height: int = 1000) -> Iterator[Any]:
    """A fresh headless page; console errors and page errors collected in `page.errors`."""
    from playwright.sync_api import sync_playwright  # noqa: PLC0415 - optional

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=executable, args=FLAGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            errors: list[str] = []
            page.on(
                "console",
                lambda m: errors.append(f"console: {m.text}") if m.type == "error" else None,
            )
            page.on("pageerror", lambda e: errors.append(f"pageerror: {e}"))
            page.errors = errors  # type: ignore[attr-defined]
            yield page
        finally:
            browser.close()
