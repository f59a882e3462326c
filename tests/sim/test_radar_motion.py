"""The simulated radar in the vehicle frame on a bend, and the ego motion its host sends
it (0x300 / 0x301): decoded off the CAN link, used for the dynamic property and the
0x201's MotionRxState, end to end from `vehicle/motion` through the radar service."""

import math
import threading

import can
import pytest

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import EGO_MOTION, RADAR_TRACKS
from aeb_radar_camera.common.messages import EgoMotion, Header
from aeb_radar_camera.services.radar.ars408 import decode_frame, ego_motion_frames, encode
from aeb_radar_camera.services.radar.ars408.records import ObjectGeneral
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from aeb_radar_camera.tools.sim.radar_feed import HostMotion, RadarFeed, state_frames
from aeb_radar_camera.tools.sim.radar_model import DynProp, RadarModel, ReceivedMotion
from aeb_radar_camera.tools.sim.scenario import (
    EgoSpec,
    Motion,
    RadarLook,
    RoadSpec,
    Scenario,
    ScenarioKind,
    SceneObject,
)
from aeb_radar_camera.tools.sim.world import World
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

QUIET = RadarLook(ghost_rate_per_cycle=0.0, split_probability=0.0, dropout_probability=0.0,
                  id_swap_probability=0.0, range_sigma_m=0.0, lateral_sigma_m=0.0,
                  velocity_sigma_mps=0.0)
R = 50.0


def bend_world(*objects: SceneObject) -> World:
    sc = Scenario(name="t", kind=ScenarioKind.NO_THREAT, ego=EgoSpec(speed_kph=36.0),
                  object=objects, road=RoadSpec(curve_start_m=0.0, radius_m=R))
    world = World(sc)
    world.step(1.0, 0.0)
    return world


def test_on_a_bend_the_road_ahead_is_off_to_the_side_and_the_outside_edge_ahead():
    """Left bend: a car on the lane 40 m further along, and a box beside the road on the
    outside 45 m along, are well to the left in the radar's frame; a guard-rail post
    beside the road on the outside, 17 m along, is in the
    straight line ahead, closing at the ego's speed and drifting right (the radar
    turns)."""
    world = bend_world(SceneObject(ObjectKind.CAR, 10.0 + 42.2, 0.0),
                       SceneObject(ObjectKind.GUARD_RAIL, 10.0 + 17.0, -3.0,
                                   size_m=(0.2, 0.1, 0.75)),
                       SceneObject(ObjectKind.BOX, 10.0 + 45.0, -3.5))
    v, omega = world.ego.speed_mps, math.radians(world.yaw_rate_dps())
    assert omega == pytest.approx(v / R)
    got = {r.source: r for r in RadarModel(QUIET).cycle(world.vehicle_bodies(), 0.0, v,
                                                       world.yaw_rate_dps())}
    car, rail, far_outside = got[0], got[1], got[2]
    assert car.y_m > 10.0 and car.x_m < 40.0
    # Far ahead on the outside of the bend, beside the road: off to the (bend's) side.
    assert far_outside.y_m > 10.0
    assert abs(rail.y_m) < 0.3 and rail.x_m == pytest.approx(17.6, abs=0.3)
    # A stationary point seen from a turning radar: x' = -v + w y, y' = -w x.
    assert rail.vx_mps == pytest.approx(-v + omega * rail.y_m, abs=1e-6)
    assert rail.vy_mps == pytest.approx(-omega * rail.x_m, abs=1e-6)
    range_rate = (rail.x_m * rail.vx_mps + rail.y_m * rail.vy_mps) / math.hypot(rail.x_m,
                                                                               rail.y_m)
    assert range_rate == pytest.approx(-v, abs=0.2)


def test_the_dynamic_property_is_the_radar_s_own_judgement_from_what_it_received():
    world = bend_world(SceneObject(ObjectKind.CAR, 10.0 + 22.2, 3.5),       # parked
                       SceneObject(ObjectKind.CAR, 12.0, 0.0, motion=Motion(speed_mps=10.0)))
    v, yaw = world.ego.speed_mps, world.yaw_rate_dps()
    bodies = world.vehicle_bodies()

    def props(received: ReceivedMotion | None) -> dict[int, int]:
        return {r.source: r.dyn_prop for r in RadarModel(QUIET).cycle(bodies, 0.0, v, yaw,
                                                                     received)}

    truth = props(None)
    assert truth == {0: DynProp.STATIONARY, 1: DynProp.MOVING}
    assert props(ReceivedMotion(v, yaw)) == truth
    # Told nothing, the radar takes itself to stand still: the parked car comes at it.
    assert props(ReceivedMotion())[0] == DynProp.ONCOMING
    # Speed without yaw rate on a bend: the parked car ahead seems to cross.
    assert props(ReceivedMotion(v, None))[0] == DynProp.CROSSING_MOVING
    assert ReceivedMotion().rx_state == 3 and ReceivedMotion(v, None).rx_state == 2
    assert ReceivedMotion(v, yaw).rx_state == 0


def test_host_motion_decodes_0x300_and_0x301_and_forgets_them_when_stale():
    now = [0]
    host = HostMotion(sensor_id=0, clock=lambda: now[0], timeout_s=0.5)
    assert host.received() == ReceivedMotion()
    for frame in ego_motion_frames(-3.0, 7.5, sensor_id=0) + ego_motion_frames(9.0, 1.0, 1):
        host.on_frame(frame)
    host.on_frame(encode(ObjectGeneral(1, 10.0, 0.0, -1.0, 0.0, 1, 5.0)))   # not for it
    got = host.received()
    assert got.speed_mps == pytest.approx(-3.0, abs=0.02)
    assert got.yaw_rate_dps == pytest.approx(7.5, abs=0.01)
    assert host.frames == 2 and host.errors == 0          # sensor 1's pair is not ours
    host.on_frame(type(ego_motion_frames(1.0, 0.0)[0])(0x300, b"\x00"))     # short frame
    assert host.errors == 1
    now[0] = int(0.6e9)
    assert host.received() == ReceivedMotion()
    state = decode_frame(*state_frames(QUIET, 0, got.rx_state)[0])[2]
    assert state.motion_rx_state == 0


def test_the_simulated_radar_reads_its_host_s_frames_off_the_slcan_link():
    """python-can's slcan interface (as the radar service opens it) writes 0x300 / 0x301;
    the feed on the other end of the pty takes them up and reports accordingly."""
    with SlcanPtyLink() as link:
        feed = RadarFeed(link, QUIET, frame_time_s=0.0)
        bus = can.Bus(interface="slcan", channel=link.path, sleep_after_open=0, bitrate=500_000)
        try:
            link.wait_open(30)
            for f in ego_motion_frames(8.0, 4.0):
                bus.send(can.Message(arbitration_id=f.arb_id, data=f.data, is_extended_id=False))
            wait_for(lambda: feed.host.frames >= 2, 30, 0.01, "0x300 and 0x301 at the radar")
            got = feed.host.received()
            assert got.speed_mps == pytest.approx(8.0, abs=0.02)
            assert got.yaw_rate_dps == pytest.approx(4.0, abs=0.01)
            car = World(Scenario(name="t", kind=ScenarioKind.THREAT,
                                 ego=EgoSpec(speed_kph=28.8),
                                 object=(SceneObject(ObjectKind.CAR, 20.0),))).bodies()
            feed.cycle(car, 0.0, 8.0, 4.0)      # turning as the host said
            kinds: dict[str, object] = {}
            while not {"RadarStateFrame", "ObjectGeneral"} <= set(kinds):
                msg = bus.recv(10)
                assert msg is not None, "the feed's cycle did not arrive"
                rec = decode_frame(msg.arbitration_id, msg.data)[2]
                kinds[type(rec).__name__] = rec
            assert kinds["RadarStateFrame"].motion_rx_state == 0      # type: ignore[attr-defined]
            assert kinds["ObjectGeneral"].dyn_prop == DynProp.STATIONARY  # type: ignore[attr-defined]
        finally:
            bus.shutdown()


@pytest.mark.slow
def test_vehicle_motion_reaches_the_simulated_radar_through_the_radar_service(tmp_path,
                                                                              router):
    """The radar service (its own process) forwards `vehicle/motion` as 0x300 / 0x301 to
    the simulated radar, which then classifies a parked car as stationary."""
    with SlcanPtyLink() as link:
        feed = RadarFeed(link, QUIET, frame_time_s=0.0)
        config = tmp_path / "radar.toml"
        config.write_text(f"""
vehicle = "ego"
[zenoh]
connect = ["{router}"]
[radar.can]
interface = "slcan"
channel = "{link.path}"
options = {{ sleep_after_open = 0 }}
[[radar.sensors]]
name = "front"
sensor_id = 0
[radar.ego_motion]
forward = true
""")
        with open_bus(router, source="sim") as bus:
            health = HealthWatch(bus)
            tracks = Collector()
            bus.subscribe(RADAR_TRACKS, tracks, sensor="front")
            proc = ServiceProcess("radar", python_module("aeb_radar_camera.services.radar",
                                                         "--config",
                                                         str(config)), tmp_path)
            stop = threading.Event()
            motion = bus.publisher(EGO_MOTION)
            parked = World(Scenario(name="t", kind=ScenarioKind.THREAT,
                                    ego=EgoSpec(speed_kph=28.8),
                                    object=(SceneObject(ObjectKind.CAR, 15.0),))).bodies()

            def simulate() -> None:           # the simulator's loop: motion and cycles
                while not stop.wait(0.075):
                    motion.put(EgoMotion(header=Header(bus.next_seq("vehicle/motion"), "sim",
                                                       wall_ns(), mono_ns()),
                                         speed_mps=8.0, yaw_rate_dps=2.0))
                    feed.cycle(parked, 0.0, 8.0, 2.0)

            loop = threading.Thread(target=simulate, daemon=True)
            try:
                health.wait_alive("radar", "front")
                loop.start()
                wait_for(lambda: feed.host.received().rx_state == 0, 60, 0.05,
                         "ego motion at the simulated radar")
                got = feed.host.received()
                assert got.speed_mps == pytest.approx(8.0, abs=0.02)
                assert got.yaw_rate_dps == pytest.approx(2.0, abs=0.01)
                tracks.wait_until(lambda m: any(t.confirmed and t.dyn_prop == DynProp.STATIONARY
                                                for t in m.tracks), 60)
            finally:
                stop.set()
                loop.join(10)
                code = proc.stop()
            assert code == 0, proc.output()
