"""The simulated sensors, pure: what the ARS408 model reports, and camera frames on which
the edge-density gate behaves as on real ones."""

import itertools
from pathlib import Path

import cv2
import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.radar_model import OBJ_CLASS, DynProp, RadarModel, in_field_of_view
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.scenario import DEFAULT_SIZE, CameraLook, RadarLook
from aeb_radar_camera.tools.sim.world import Body

CALIBRATION = Path(__file__).resolve().parents[2] / "deploy/calibration/d435_848x480.toml"
QUIET = RadarLook(ghost_rate_per_cycle=0.0, split_probability=0.0, dropout_probability=0.0,
                  id_swap_probability=0.0)


def body(kind: ObjectKind, x: float, y: float = 0.0, index: int = 0, vx: float = 0.0,
         vy: float = 0.0, yaw: float = 0.0) -> Body:
    length, width, height = DEFAULT_SIZE[kind]
    return Body(index, kind, x, y, yaw, length, width, height, vx, vy)


def test_object_mode_reports_the_rear_face_with_noise_relative_speed_and_stable_ids():
    model = RadarModel(QUIET, seed=1)
    car = body(ObjectKind.CAR, 32.2, 0.5)          # rear face at x = 30 m
    cycles = [model.cycle([car], ego_x_m=10.0, ego_speed_mps=8.0) for _ in range(200)]
    assert all(len(c) == 1 for c in cycles)
    xs = np.array([c[0].x_m for c in cycles])
    ys = np.array([c[0].y_m for c in cycles])
    assert xs.mean() == pytest.approx(20.0, abs=0.05)
    assert xs.std() == pytest.approx(QUIET.range_sigma_m, rel=0.25)
    assert ys.mean() == pytest.approx(0.0, abs=0.05)   # nearest point of the rear face
    assert np.mean([c[0].vx_mps for c in cycles]) == pytest.approx(-8.0, abs=0.05)
    assert {c[0].id for c in cycles} == {cycles[0][0].id}
    first = cycles[0][0]
    assert first.meas_state == 1 and cycles[1][0].meas_state == 2
    assert first.dyn_prop == DynProp.STATIONARY and first.obj_class == OBJ_CLASS[ObjectKind.CAR]
    assert first.source == 0


def test_dynamic_property_from_absolute_motion():
    model = RadarModel(QUIET, seed=2)
    objs = [body(ObjectKind.BICYCLE, 20.0, 0.0, 0, vx=3.0),
            body(ObjectKind.PEDESTRIAN, 15.0, -3.0, 1, vy=1.5),
            body(ObjectKind.CAR, 40.0, 3.5, 2, vx=-5.0)]
    got = {r.source: r.dyn_prop for r in model.cycle(objs, 0.0, 5.0)}
    assert got == {0: DynProp.MOVING, 1: DynProp.CROSSING_MOVING, 2: DynProp.ONCOMING}


def test_a_pedestrian_behind_a_parked_car_is_hidden_until_it_steps_out():
    model = RadarModel(QUIET, seed=3)
    parked = body(ObjectKind.CAR, 30.0, -2.7, 0)
    hidden = body(ObjectKind.PEDESTRIAN, 33.0, -2.4, 1)
    assert {r.source for r in model.cycle([parked, hidden], 15.0, 5.0)} == {0}
    out = body(ObjectKind.PEDESTRIAN, 33.0, -1.0, 1)
    assert {r.source for r in model.cycle([parked, out], 15.0, 5.0)} == {0, 1}


def test_field_of_view():
    assert in_field_of_view(20.0, 0.0) and in_field_of_view(60.0, 30.0)
    assert not in_field_of_view(5.0, 20.0)       # beyond +-60 deg
    assert in_field_of_view(200.0, 10.0)          # far scan, +-9 deg
    assert not in_field_of_view(200.0, 60.0)
    assert not in_field_of_view(-1.0, 0.0)


def test_ghosts_come_at_the_configured_rate_and_never_last_three_cycles():
    look = RadarLook(ghost_rate_per_cycle=0.5, split_probability=0.0, dropout_probability=0.0)
    model = RadarModel(look, seed=4)
    n_cycles = 2000
    ghost_ids_per_cycle = []
    for _ in range(n_cycles):
        ghosts = [r for r in model.cycle([], 0.0, 5.0) if r.source == -1]
        ghost_ids_per_cycle.append({g.id for g in ghosts})
    # A ghost keeps its ID for at most two consecutive cycles: the tracker's 3-hit
    # confirmation never promotes it.
    for prev, cur, nxt in zip(ghost_ids_per_cycle, ghost_ids_per_cycle[1:],
                              ghost_ids_per_cycle[2:], strict=False):
        assert not (prev & cur & nxt)
    new = sum(len(cur - prev) for prev, cur in zip([set(), *ghost_ids_per_cycle],
                                                   ghost_ids_per_cycle, strict=False))
    assert new / n_cycles == pytest.approx(0.5, rel=0.15)


def test_large_objects_sometimes_split_and_clusters_come_several_per_car():
    look = RadarLook(ghost_rate_per_cycle=0.0, split_probability=0.5, dropout_probability=0.0)
    model = RadarModel(look, seed=5)
    car = body(ObjectKind.CAR, 25.0, 0.0)
    counts = [len(model.cycle([car], 0.0, 5.0)) for _ in range(400)]
    assert set(counts) == {1, 2}
    assert counts.count(2) / len(counts) == pytest.approx(0.5, abs=0.1)
    clusters = RadarModel(RadarLook(mode="clusters", ghost_rate_per_cycle=0.0,
                                    dropout_probability=0.0), seed=6)
    cycle = clusters.cycle([car, body(ObjectKind.PEDESTRIAN, 15.0, 2.0, 1)], 0.0, 5.0)
    per_source = {s: sum(1 for r in cycle if r.source == s) for s in (0, 1)}
    assert 3 <= per_source[0] <= 5 and 1 <= per_source[1] <= 2
    assert [r.id for r in cycle] == list(range(len(cycle)))   # cluster IDs are list indices
    car_points = [r for r in cycle if r.source == 0]
    assert all(21.5 < r.x_m < 28.0 and abs(r.y_m) < 1.5 for r in car_points)


def test_object_ids_swap_sometimes():
    look = RadarLook(ghost_rate_per_cycle=0.0, split_probability=0.0, dropout_probability=0.0,
                     id_swap_probability=0.2)
    model = RadarModel(look, seed=7)
    objs = [body(ObjectKind.CAR, 30.0, 0.0, 0), body(ObjectKind.CAR, 30.0, -4.0, 1)]
    ids = [{r.source: r.id for r in model.cycle(objs, 0.0, 5.0)} for _ in range(50)]
    assert any(a[0] == b[1] for a, b in itertools.pairwise(ids))


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    """The plain rendering (smooth road, open sky) of the still test scenes."""
    return Renderer(Calibration.load(CALIBRATION), seed=3, roadside=False)


def roi(cal: Calibration, x: float, y: float) -> tuple[int, int, int, int]:
    """The paper's ROI: the 0-2.2 m column at (x, y), 22 px padding, clipped."""
    uv, _ = cal.project(np.array([[x, y, 0.0], [x, y, 2.2]]))
    return (max(int(uv[:, 0].min()) - 22, 0), max(int(uv[:, 1].min()) - 22, 0),
            min(int(uv[:, 0].max()) + 22, cal.width), min(int(uv[:, 1].max()) + 22, cal.height))


def density(gray: np.ndarray, box: tuple[int, int, int, int]) -> float:
    x0, y0, x1, y1 = box
    edges = cv2.Canny(gray[y0:y1, x0:x1], 40, 120)
    return float(np.count_nonzero(edges)) / edges.size


def gray_frame(renderer: Renderer, bodies: list[Body], ego_x: float = 0.0) -> np.ndarray:
    return decode_gray(encode_jpeg(renderer.render(bodies, ego_x), 80))


def test_frames_have_the_calibration_size_and_change_as_the_ego_moves(renderer):
    a = renderer.render([], 0.0)
    assert a.shape == (480, 848, 3) and a.dtype == np.uint8
    b = renderer.render([], 1.5)
    # The road moves under the car; the sky does not.
    assert np.abs(a[400:].astype(int) - b[400:]).mean() > 2.0
    assert np.abs(a[:100, 340:508].astype(int) - b[:100, 340:508]).mean() < 4.0


@pytest.mark.parametrize("kind", [k for k in ObjectKind if k.is_obstacle])
def test_obstacle_rois_are_dense_in_edges_and_empty_road_is_not(renderer, kind):
    """The paper's gate (Canny 40/120, tau 0.025) on the frames fusion would receive
    (JPEG q80, decoded to grey on the project's one path)."""
    cal = renderer.cal
    length = DEFAULT_SIZE[kind][0]
    for near in (5.0, 12.0, 24.0):
        box = roi(cal, near, 0.0)
        with_obj = gray_frame(renderer, [body(kind, near + length / 2)])
        without = gray_frame(renderer, [])
        assert density(with_obj, box) > 0.025, f"{kind.value} at {near} m"
        assert density(without, box) < 0.015, f"empty road at {near} m"


def test_sky_is_sparse_and_dusk_lowers_contrast():
    cal = Calibration.load(CALIBRATION)
    day = Renderer(cal, seed=1, roadside=False)
    dusk = Renderer(cal, seed=1, look=CameraLook(brightness=0.3, noise=3.0), roadside=False)
    ped = [body(ObjectKind.PEDESTRIAN, 10.0)]
    sky_box = (300, 10, 420, 120)
    assert density(gray_frame(day, ped), sky_box) < 0.002
    box = roi(cal, 10.0 - DEFAULT_SIZE[ObjectKind.PEDESTRIAN][0] / 2, 0.0)
    assert density(gray_frame(dusk, ped), box) < density(gray_frame(day, ped), box)
    assert gray_frame(dusk, ped).mean() < 0.5 * gray_frame(day, ped).mean()


def test_sensor_noise_is_grey_and_a_scene_renders_the_same_whatever_came_before():
    from aeb_radar_camera.tools.sim.render import Light

    cal = Calibration.load(CALIBRATION)
    ped = [body(ObjectKind.PEDESTRIAN, 10.0)]
    quiet = Renderer(cal, seed=1, look=CameraLook(noise=0.0)).render(ped, 0.0).astype(int)
    r = Renderer(cal, seed=1, look=CameraLook(noise=4.0))
    r.new_scene(11)
    first = r.render(ped, 0.0)
    noise = first.astype(int) - quiet
    assert noise.std() > 2.0                      # there is noise ...
    sky = noise[:100]                             # ... the same on the three channels
    assert (sky[..., 0] == sky[..., 1]).all() and (sky[..., 1] == sky[..., 2]).all()
    # another scene, a night one (its own lighting), then the first scene again
    r.new_scene(12)
    r.render([body(ObjectKind.CAR, 20.0)], 3.0, [Light(40.0, 2.0, 6.0)], headlights=True)
    r.new_scene(11)
    assert np.array_equal(r.render(ped, 0.0), first)


def test_nearer_objects_hide_farther_ones(renderer):
    far = body(ObjectKind.CAR, 15.0, 0.0, 0)
    near = body(ObjectKind.BOX, 12.0, 0.0, 1)
    x0, _, x1, y1 = roi(renderer.cal, 11.7, 0.0)
    # The box's face, a few pixels inside its outline.
    box_px = (slice(y1 - 40, y1 - 27), slice((x0 + x1) // 2 - 8, (x0 + x1) // 2 + 8))
    empty = renderer.render([], 0.0).astype(int)[box_px]
    only_far = renderer.render([far], 0.0).astype(int)[box_px]
    only_near = renderer.render([near], 0.0).astype(int)[box_px]
    both = renderer.render([far, near], 0.0).astype(int)[box_px]
    assert np.abs(only_far - empty).mean() > 20.0      # the car stands behind the box
    assert np.abs(both - only_near).mean() < 6.0       # and the box hides it


def test_feed_paces_bursts_stamps_each_write_and_then_lets_the_reader_run():
    from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, object_cycle_frames
    from aeb_radar_camera.tools.sim.radar_feed import BURST_FRAMES, FRAME_TIME_S, RadarFeed

    events: list[tuple[str, int]] = []
    clock = {"now": 1_000_000}

    class Sink:
        def send(self, frames: object) -> None:
            events.append(("write", len(frames)))     # type: ignore[arg-type]

    def tick() -> int:
        clock["now"] += 1_000
        events.append(("clock", clock["now"]))
        return clock["now"]

    def sleep(s: float) -> None:
        clock["now"] += round(s * 1e9)

    feed = RadarFeed(Sink(), RadarLook(), clock=tick, sleep=sleep,
                     yield_cpu=lambda: events.append(("yield", 0)))
    frames = object_cycle_frames([ObjectGeneral(i, 10.0 + i, 0.0, -1.0, 0.0, 0, 5.0)
                                  for i in range(6)], 3)      # 7 frames: two bursts
    first, last = feed.send_paced(frames)
    writes = [i for i, e in enumerate(events) if e[0] == "write"]
    assert [events[i][1] for i in writes] == [BURST_FRAMES, len(frames) - BURST_FRAMES]
    for i in writes:      # each write: stamped at once, then the CPU is offered
        assert events[i + 1][0] == "clock" and events[i + 2] == ("yield", 0)
    assert last == events[writes[-1] + 1][1]            # the last write's stamp
    assert last - first >= BURST_FRAMES * FRAME_TIME_S * 1e9      # paced at the bus rate
