"""OpenRTM data types (`RTC::Timed*`, any IDL struct) to sdrpeer values and back.

How it works: omniORBpy describes every IDL type by a descriptor tuple (`omniORB.findType(repo
id)`): a struct is `(tv_struct, class, repo id, name, field, descriptor, field, descriptor, ...)`,
a sequence `(tv_sequence, element, bound)`, a string `(tv_string, bound)`, a scalar a bare int.
The conversion walks that descriptor, so any data type an RTC's DataPort declares converts, with
three kinds of result (the table is in docs/openrtm.md):

1. `RTC::TimedPose2D` <-> `Pose` and `RTC::TimedVelocity2D` <-> `Velocity` (sdrpeer.sdk's robot
   types): `tm` is `stamp` (unix seconds), the heading a rotation about z (`qz`, `qw`), `va` is
   `wz`; `frame` is empty on the way out and ignored on the way in.
2. A `Timed*` type of a `tm` and a scalar, string or sequence `data` (`TimedLong`, `TimedDouble`,
   `TimedString`, `TimedOctetSeq`, `TimedDoubleSeq`, ...): just `data` (an int, float, bool, str,
   bytes or list); the time stamp is dropped on the way out and is the time of writing on the way
   in (what `OpenRTM_aist.setTimestamp` does).
3. Any other struct: a map of its fields, recursively; a `RTC::Time` field is unix seconds.
   Missing fields are zero on the way in.

It needs `omniORB` and the RTC stubs (OpenRTM-aist-Python): only the openrtm host imports it.
"""

from __future__ import annotations

import math
import time
from typing import Any

import omniORB
from omniORB import tcInternal as tc

from sdrpeer.errors import RtcDataError
from sdrpeer.sdk.robot_types import Pose, Velocity

TIME_ID = "IDL:RTC/Time:1.0"
POSE2D_ID = "IDL:RTC/TimedPose2D:1.0"
VELOCITY2D_ID = "IDL:RTC/TimedVelocity2D:1.0"

MAPPED_TYPES: dict[str, type] = {POSE2D_ID: Pose, VELOCITY2D_ID: Velocity}
"""Data types that map onto one of sdrpeer's robot types (a typed sdrpeer port)."""

_INTS = {tc.tv_short, tc.tv_long, tc.tv_ushort, tc.tv_ulong, tc.tv_longlong, tc.tv_ulonglong}
_FLOATS = {tc.tv_float, tc.tv_double, tc.tv_longdouble}


def descriptor(repo_id: str) -> Any:
    """The omniORB descriptor of an IDL type (KeyError if its stubs are not loaded)."""
    desc = omniORB.findType(repo_id)
    if desc is None:
        raise KeyError(f"no IDL type {repo_id!r} is loaded (import its stubs first)")
    return desc


def _resolve(desc: Any) -> Any:
    """A descriptor with aliases and indirections taken away."""
    while isinstance(desc, tuple) and desc[0] in (tc.tv_alias, tc.tv__indirect):
        desc = desc[3] if desc[0] == tc.tv_alias else desc[1][0]
    return desc


def _fields(desc: Any) -> list[tuple[str, Any]]:
    """A struct descriptor's (name, descriptor) pairs in order."""
    return list(zip(desc[4::2], desc[5::2], strict=True))


def default_value(desc: Any) -> Any:
    """The zero value of an IDL type: what a fresh port's data holds."""
    desc = _resolve(desc)
    if isinstance(desc, int):
        if desc in _INTS:
            return 0
        if desc in _FLOATS:
            return 0.0
        if desc == tc.tv_boolean:
            return False
        if desc == tc.tv_char:
            return "\0"
        if desc == tc.tv_octet:
            return 0
        return None
    kind = desc[0]
    if kind == tc.tv_struct:
        return desc[1](*(default_value(d) for _, d in _fields(desc)))
    if kind == tc.tv_sequence:
        return b"" if _resolve(desc[1]) in (tc.tv_octet, tc.tv_char) else []
    if kind in (tc.tv_string, tc.tv_wstring):
        return ""
    if kind == tc.tv_enum:
        return desc[3][0]
    if kind == tc.tv_array:
        return [default_value(desc[1])] * desc[2]
    return None


def _is_simple_timed(desc: Any) -> bool:
    """A struct of `tm` (RTC::Time) and a `data` that is not a struct: kind 2 of the header."""
    fields = _fields(desc)
    if len(fields) != 2 or fields[0][0] != "tm" or fields[1][0] != "data":
        return False
    data = _resolve(fields[1][1])
    if not _is_time(fields[0][1]):
        return False
    return isinstance(data, int) or data[0] != tc.tv_struct


def _is_time(desc: Any) -> bool:
    desc = _resolve(desc)
    return isinstance(desc, tuple) and desc[0] == tc.tv_struct and desc[2] == TIME_ID


def _stamp(t: Any) -> float:
    return float(t.sec) + float(t.nsec) * 1e-9


def _time(stamp: float) -> Any:
    import RTC  # noqa: PLC0415 - the stubs register themselves with omniORB on import

    sec = math.floor(stamp)
    return RTC.Time(int(sec), min(round((stamp - sec) * 1e9), 999_999_999))


def _plain(value: Any, desc: Any) -> Any:
    """An IDL value as msgpack-able Python (kind 3 of the header)."""
    desc = _resolve(desc)
    if isinstance(desc, int):
        return value
    kind = desc[0]
    if kind == tc.tv_struct:
        if desc[2] == TIME_ID:
            return _stamp(value)
        return {name: _plain(getattr(value, name), d) for name, d in _fields(desc)}
    if kind in (tc.tv_sequence, tc.tv_array):
        if isinstance(value, bytes | str):
            return value
        return [_plain(v, desc[1]) for v in value]
    if kind == tc.tv_enum:
        return str(value)
    return value


def to_sdrpeer(value: Any, repo_id: str) -> Any:
    """An RTC port's data as the value an sdrpeer port carries."""
    if repo_id == POSE2D_ID:
        h = value.data.heading
        return Pose(
            stamp=_stamp(value.tm),
            frame="",
            x=value.data.position.x,
            y=value.data.position.y,
            qz=math.sin(h / 2),
            qw=math.cos(h / 2),
        )
    if repo_id == VELOCITY2D_ID:
        d = value.data
        return Velocity(stamp=_stamp(value.tm), frame="", vx=d.vx, vy=d.vy, wz=d.va)
    desc = _resolve(descriptor(repo_id))
    if _is_simple_timed(desc):
        return _plain(value.data, _fields(desc)[1][1])
    return _plain(value, desc)


def _field(value: Any, name: str, default: Any) -> Any:
    if isinstance(value, dict):
        return value.get(name, default)
    return getattr(value, name, default)


def _idl(value: Any, desc: Any, where: str) -> Any:
    """Python `value` as the IDL type `desc` (fields missing: zero)."""
    desc = _resolve(desc)
    try:
        if isinstance(desc, int):
            if desc in _INTS or desc == tc.tv_octet:
                return int(value)
            if desc in _FLOATS:
                return float(value)
            if desc == tc.tv_boolean:
                return bool(value)
            return value
        kind = desc[0]
        if kind == tc.tv_struct:
            if desc[2] == TIME_ID:
                return _time(time.time() if value is None else float(value))
            args = []
            for n, d in _fields(desc):
                v = _field(value, n, None)
                if v is not None:
                    args.append(_idl(v, d, f"{where}.{n}"))
                elif _is_time(d):
                    args.append(_time(time.time()))
                else:
                    args.append(default_value(d))
            return desc[1](*args)
        if kind in (tc.tv_sequence, tc.tv_array):
            if _resolve(desc[1]) in (tc.tv_octet, tc.tv_char):
                return bytes(value) if not isinstance(value, str) else value.encode()
            return [_idl(v, desc[1], f"{where}[{i}]") for i, v in enumerate(value)]
        if kind in (tc.tv_string, tc.tv_wstring):
            return str(value)
        if kind == tc.tv_enum:
            return next(e for e in desc[3] if str(e) == str(value) or e._v == value)
    except (TypeError, ValueError, StopIteration) as exc:
        raise RtcDataError(f"{where}: {value!r} does not fit: {exc}") from None
    return value


def from_sdrpeer(value: Any, repo_id: str) -> Any:
    """An sdrpeer value as the data an RTC port of type `repo_id` takes."""
    import RTC  # noqa: PLC0415 - see _time

    if repo_id == POSE2D_ID:
        qx, qy = _field(value, "qx", 0.0), _field(value, "qy", 0.0)
        qz, qw = _field(value, "qz", 0.0), _field(value, "qw", 1.0)
        heading = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
        return RTC.TimedPose2D(
            _time(_field(value, "stamp", None) or time.time()),
            RTC.Pose2D(
                RTC.Point2D(float(_field(value, "x", 0.0)), float(_field(value, "y", 0.0))),
                heading,
            ),
        )
    if repo_id == VELOCITY2D_ID:
        return RTC.TimedVelocity2D(
            _time(_field(value, "stamp", None) or time.time()),
            RTC.Velocity2D(
                float(_field(value, "vx", 0.0)),
                float(_field(value, "vy", 0.0)),
                float(_field(value, "wz", 0.0)),
            ),
        )
    desc = _resolve(descriptor(repo_id))
    if _is_simple_timed(desc):
        data = _idl(value, _fields(desc)[1][1], repo_id)
        return desc[1](_time(time.time()), data)
    return _idl(value, desc, repo_id)
