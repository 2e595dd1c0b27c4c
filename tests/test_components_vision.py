"""Cameras and anomaly detection: the synthetic scene, the detector, both as running components."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest

from components.anomaly_detection import AnomalyDetection, find_blobs, find_hazard
from components.camera import Camera, OmnidirectionalCamera
from components.scene import DECOY_LEVEL, HAZARD_LEVEL, Scene
from sdrpeer.sdk import ComponentRunner, LifecycleState
from tests.virtual_time import run_virtual
from tests.wait import until_async


class ListSink:
    """An OutPort sink that keeps every value."""

    def __init__(self) -> None:
        self.values: list[Any] = []

    def offer(self, value: Any) -> bool:
        self.values.append(value)
        return True


def hazard_times(scene: Scene, visible: bool, n: int = 5) -> list[float]:
    """The first `n` frame times (10 Hz) at which the hazard is (not) in view."""
    return [t for t in (k / 10 for k in range(400)) if scene.hazard_visible(t) == visible][:n]


# -- scene ---------------------------------------------------------------------------------


def test_scene_is_deterministic_per_seed_and_moves() -> None:
    a, b, c = Scene(5, 160, 120), Scene(5, 160, 120), Scene(6, 160, 120)
    assert a.render(1.0) == b.render(1.0)
    assert a.render(1.0) != c.render(1.0)
    assert a.render(1.0) != a.render(1.1)
    assert len(a.render(0.0)) == 160 * 120


def test_hazard_appears_and_disappears_on_its_schedule() -> None:
    scene = Scene(3, 160, 120, period=4.0, on_time=1.0)
    shown = [scene.hazard_visible(k / 10) for k in range(80)]
    assert 15 <= sum(shown) <= 25  # a quarter of the time
    assert any(shown[i] != shown[i + 1] for i in range(79))
    t = hazard_times(scene, True, 1)[0]
    assert HAZARD_LEVEL in scene.render(t)
    assert HAZARD_LEVEL not in scene.render(hazard_times(scene, False, 1)[0])
    assert DECOY_LEVEL in scene.render(t)  # the decoy is always there


# -- detector ------------------------------------------------------------------------------


@pytest.mark.parametrize(("seed", "wrap", "size"), [(1, False, (160, 120)), (2, True, (320, 160))])
def test_detector_finds_the_hazard_where_it_is_and_not_when_absent(
    seed: int, wrap: bool, size: tuple[int, int]
) -> None:
    w, h = size
    scene = Scene(seed, w, h, wrap=wrap)
    for t in hazard_times(scene, True, 20):
        blob = find_hazard(scene.render(t), w, h, wrap=wrap)
        truth = scene.hazard_at(t)
        assert blob is not None, t
        assert truth is not None
        dx = abs(blob.x - truth[0])
        assert min(dx, w - dx) < 1.5, (t, blob, truth)
        assert abs(blob.y - truth[1]) < 1.5
    for t in hazard_times(scene, False, 20):
        assert find_hazard(scene.render(t), w, h, wrap=wrap) is None, t


def test_detector_rejects_bright_bars_and_dim_discs_by_shape_and_level() -> None:
    w, h = 40, 30
    frame = bytearray(b"\x50" * (w * h))
    for y in range(5, 9):  # a bright 20x4 bar
        frame[y * w + 5 : y * w + 25] = b"\xf5" * 20
    for y, half in zip(range(18, 27), (2, 3, 4, 4, 4, 4, 4, 3, 2), strict=True):  # a dim disc
        frame[y * w + 20 - half : y * w + 21 + half] = b"\xa0" * (2 * half + 1)
    blobs = find_blobs(bytes(frame), w, h, 230)
    assert [(b.width, b.height, b.area) for b in blobs] == [(20, 4, 80)]
    assert find_hazard(bytes(frame), w, h) is None
    assert find_hazard(bytes(frame), w, h, threshold=150) is not None  # the disc, once bright


def test_detector_joins_an_object_cut_by_the_panorama_seam() -> None:
    w, h = 64, 32
    frame = bytearray(w * h)
    for y, half in zip(range(10, 21), (2, 4, 4, 5, 5, 5, 5, 5, 4, 4, 2), strict=True):
        for x in range(-half, half + 1):
            frame[y * w + x % w] = 250
    plain = find_hazard(bytes(frame), w, h)
    seam = find_hazard(bytes(frame), w, h, wrap=True)
    assert plain is None  # two half discs
    assert seam is not None
    assert min(seam.x, w - seam.x) < 0.5
    assert seam.y == pytest.approx(15.0)


def test_detector_is_fast_enough_for_10_hz() -> None:
    scene = Scene(1, 160, 120)
    frames = [scene.render(t) for t in hazard_times(scene, True, 20)]
    start = time.perf_counter()
    for f in frames:
        find_hazard(f, 160, 120)
    assert (time.perf_counter() - start) / len(frames) < 0.02  # 20 ms, a fifth of a period


def test_detector_refuses_a_frame_of_the_wrong_size() -> None:
    with pytest.raises(ValueError, match="is not 10x10"):
        find_blobs(b"\x00" * 99, 10, 10, 200)


# -- as components -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "size"), [(Camera, (160, 120)), (OmnidirectionalCamera, (320, 160))]
)
def test_cameras_publish_frames_at_their_rate_and_size(
    cls: type[Camera], size: tuple[int, int]
) -> None:
    """On virtual loop time (tests/virtual_time.py) the count is exact, however busy the machine."""
    w, h = size
    cam = cls(params={"rate": 100.0})
    sink = ListSink()
    cam.image.attach(sink)

    async def scenario() -> None:
        runner = ComponentRunner(cam)
        await runner.initialize()
        await runner.activate()
        await asyncio.sleep(0.195)
        assert len(sink.values) == 20  # 100 Hz: at 0, 0.01, ..., 0.19 s
        await runner.deactivate()
        await asyncio.sleep(1.0)
        assert len(sink.values) == 20  # paced by the rate, and only while ACTIVE
        await runner.finalize()

    run_virtual(scenario())
    first = sink.values[0]
    assert set(first) == {"w", "h", "seq", "ts", "pixels"}
    assert (first["w"], first["h"], len(first["pixels"])) == (w, h, w * h)
    assert [v["seq"] for v in sink.values[:5]] == [1, 2, 3, 4, 5]
    assert first["pixels"] == cam.scene.render(0.0)


async def test_anomaly_detection_raises_the_alarm_per_frame() -> None:
    scene = Scene(1, 160, 120)
    det = AnomalyDetection()
    sink = ListSink()
    det.alarm.attach(sink)
    runner = ComponentRunner(det)
    await runner.initialize()
    await runner.activate()
    with_hazard = hazard_times(scene, True, 1)[0]
    without = hazard_times(scene, False, 1)[0]
    for seq, t in enumerate((with_hazard, without), start=1):
        frame = {"w": 160, "h": 120, "seq": seq, "ts": 0.0, "pixels": scene.render(t)}
        det.image.deliver(frame, seq, "cam")
        await until_async(
            f"detection {seq}",
            lambda: len(sink.values),
            lambda v, n=seq: v == n,  # type: ignore[misc]
        )
    await runner.finalize()
    hit, miss = sink.values
    truth = scene.hazard_at(with_hazard)
    assert truth is not None
    assert hit["alarm"] is True
    assert hit["source"] == 1
    assert hit["where"] == pytest.approx(list(truth), abs=1.5)
    assert miss == {"alarm": False, "ts": miss["ts"], "where": None, "source": 2}
    assert runner.state is LifecycleState.FINALIZED
