"""OpenRTM-aist RT-Components hosted unmodified as sdrpeer components (the `openrtm` launcher).

How it works: `python -m sdrpeer.openrtm path/to/Module.py[:TypeName] [--param k=v ...]` is a
component host (docs/protocol.md) like `python -m sdrpeer.host`: it starts OpenRTM's manager in
the process, has the module's `XxxInit(manager)` register the RTC's factory, creates the RTC and
its bridge (sdrpeer.openrtm.runtime), builds the sdrpeer Component that stands for it from its
port profile (sdrpeer.openrtm.component; values mapped by sdrpeer.openrtm.values) and serves the
control channel with sdrpeer.host's `Host`. Needs the `openrtm` extra (OpenRTM-aist-Python and
omniORBpy); `sdrpeer.launch.openrtm.available()` says whether they are here. docs/openrtm.md.
"""
