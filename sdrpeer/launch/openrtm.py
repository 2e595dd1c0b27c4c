"""Whether the `openrtm` launcher can run here: OpenRTM-aist-Python is an optional extra.

How it works: `available()` is None when OpenRTM-aist-Python, its RTC stubs and omniORBpy can be
imported (found, not imported: cheap, cached), else the reason and how to install them. The
launcher (`OpenRtmLauncher` in sdrpeer.launch.launchers) refuses with that reason, and an agent
offers `openrtm` in its gossiped launch policy only where it is available (sdrpeer.config), so
the allocator never places an RTC on a robot without OpenRTM.
"""

from __future__ import annotations

import functools
import importlib.util

INSTALL_HINT = (
    "install the openrtm extra: pip install 'sdrpeer[openrtm]' "
    "--find-links third_party/wheels (docs/openrtm.md)"
)


@functools.cache
def available() -> str | None:
    """None if OpenRTM-aist-Python and omniORBpy can be imported here, else why not."""
    missing = [m for m in ("omniORB", "OpenRTM_aist", "RTC") if importlib.util.find_spec(m) is None]
    if not missing:
        return None
    modules = ", ".join(missing)
    return f"OpenRTM-aist-Python is not installed here (no module {modules}); {INSTALL_HINT}"
