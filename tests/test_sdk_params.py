"""Typed params: conversion from CLI strings and msgpack values, bounds, choices, errors."""

from __future__ import annotations

from typing import Any

import pytest

from sdrpeer.sdk import Component, Param, ParamError
from sdrpeer.sdk.errors import ComponentError


class Camera(Component):
    rate = Param(float, 10.0, "frames per second", min=0.5, max=60)
    width = Param(int, 640, "pixels")
    mode = Param(str, "rgb", choices=["rgb", "gray"])
    flip = Param(bool, False)


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("rate", "10", 10.0),
        ("rate", "2.5", 2.5),
        ("rate", 3, 3.0),
        ("rate", 60, 60.0),
        ("width", "320", 320),
        ("width", " 1024 ", 1024),
        ("width", 800.0, 800),
        ("width", -1, -1),
        ("mode", "gray", "gray"),
        ("flip", "true", True),
        ("flip", "False", False),
        ("flip", "yes", True),
        ("flip", "0", False),
        ("flip", 1, True),
        ("flip", True, True),
    ],
)
def test_conversion(name: str, value: Any, expected: Any) -> None:
    out = Camera._sdk_params[name].convert(value)
    assert out == expected
    assert type(out) is type(expected)


@pytest.mark.parametrize(
    ("name", "value", "fragment"),
    [
        ("rate", "fast", "expected float, got 'fast'"),
        ("rate", True, "expected float, got True"),
        ("rate", "nan", "expected float"),
        ("rate", 0.1, "0.1 below min 0.5"),
        ("rate", 61, "61.0 above max 60"),
        ("width", "10.5", "expected int, got '10.5'"),
        ("width", 1.5, "expected int, got 1.5"),
        ("width", False, "expected int"),
        ("mode", "hsv", "'hsv' not in 'rgb', 'gray'"),
        ("mode", 3, "expected str, got 3"),
        ("flip", "maybe", "expected bool, got 'maybe'"),
        ("flip", 2, "expected bool"),
        ("flip", None, "expected bool, got None"),
    ],
)
def test_bad_values_name_the_param_and_type(name: str, value: Any, fragment: str) -> None:
    with pytest.raises(ParamError) as info:
        Camera._sdk_params[name].convert(value)
    assert str(info.value).startswith(f"param {name!r}: ")
    assert fragment in str(info.value)
    assert info.value.name == name


def test_instances_have_their_own_values_and_defaults() -> None:
    a = Camera("a", params={"rate": "20", "flip": "on"})
    b = Camera("b")
    assert a.rate == 20.0
    assert a.flip is True
    assert b.rate == 10.0
    assert b.param_values() == {"rate": 10.0, "width": 640, "mode": "rgb", "flip": False}


def test_assignment_from_component_code_is_checked() -> None:
    cam = Camera()
    cam.width = "1280"
    assert cam.width == 1280
    with pytest.raises(ParamError):
        cam.width = "wide"
    assert cam.width == 1280


def test_unknown_param_is_rejected_with_the_known_names() -> None:
    with pytest.raises(ParamError, match=r"param 'fps': unknown param \(known: rate, width"):
        Camera(params={"fps": 3})


def test_metadata() -> None:
    info = Camera.params()
    assert list(info) == ["rate", "width", "mode", "flip"]
    assert info["rate"].type == "float"
    assert info["rate"].doc == "frames per second"
    assert info["rate"].to_map() == {
        "name": "rate",
        "type": "float",
        "default": 10.0,
        "doc": "frames per second",
        "min": 0.5,
        "max": 60,
    }
    assert info["mode"].choices == ("rgb", "gray")


def test_bad_declarations_fail_at_class_creation() -> None:
    with pytest.raises(ParamError, match="param 'n': expected int"):

        class _Bad(Component):
            n = Param(int, "many")  # type: ignore[type-var]

    with pytest.raises(TypeError, match="int, float, str or bool"):
        Param(list, [])  # type: ignore[type-var]

    with pytest.raises(ComponentError, match=r"_Hook\.n: on_change method 'nope' is not defined"):

        class _Hook(Component):
            n = Param(int, 1, on_change="nope")

    with pytest.raises(ComponentError, match="name reserved"):

        class _Reserved(Component):
            log = Param(str, "x")  # type: ignore[assignment]


def test_subclass_inherits_and_overrides_params() -> None:
    class Base(Component):
        a = Param(int, 1)
        b = Param(int, 2)

    class Child(Base):
        b = Param(int, 20)
        c = Param(str, "c")

    assert list(Child.params()) == ["a", "b", "c"]
    assert Child().b == 20
    assert list(Base.params()) == ["a", "b"]
