"""SIMULATION for the two-board walk-through test (tests/system/test_deploy_walkthrough.py):
ECU A's hardware stand-ins, run inside ECU A's network namespace. The ARS408 on a pty
behaving as an slcan USB-CAN adapter, the brake actuator on a pty, and the closed-loop
simulator (the world the camera plugin renders, the ego's motion) on ECU A's router.

    python -m tests.system.walkthrough_sim OUT --connect tcp/127.0.0.1:7447

Writes OUT/ports.json (the two pty paths, for the configs' [radar.can] and
[brake.serial]) as soon as they exist, then waits for the router (started after it by
`aeb up`) and prints one JSON line per event: every brake state it sees, `armed` once
the stack is idle and armed, then the scenario's verdict and the brake levels the
actuator got. Exits 0 after the scenario, 1 when the stack never armed.
"""

import argparse
import json
import sys
from pathlib import Path

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import BRAKE_STATUS
from aeb_radar_camera.common.messages import BrakeStatus
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.runner import SimActuatorView, Simulator
from aeb_radar_camera.tools.sim.scenario import RadarLook, find_scenario, load_scenario

SCENARIO = "pedestrian_standing_20kph"


def say(**event: object) -> None:
    print(json.dumps(event), flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("out")
    parser.add_argument("--connect", required=True)
    parser.add_argument("--arm-timeout", type=float, default=180.0)
    args = parser.parse_args(argv)
    out = Path(args.out)
    with SlcanPtyLink() as link:
        actuator, _pair = SimActuator.on_pty(out / "actuator")
        actuator.start()
        try:
            tmp = out / "ports.json.tmp"
            tmp.write_text(json.dumps({"radar": link.path, "actuator": str(out / "actuator")}))
            tmp.replace(out / "ports.json")
            settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(args.connect,))
            with Bus.open(settings, "ego", "sim") as bus:
                states: list[str] = []

                def on_status(msg: BrakeStatus, key: str) -> None:
                    if not states or states[-1] != msg.state.value:
                        states.append(msg.state.value)
                        say(brake_state=msg.state.value, reason=msg.reason)

                bus.subscribe(BRAKE_STATUS, on_status)
                sim = Simulator(bus, RadarFeed(link, RadarLook()),
                                SimActuatorView(actuator)).start()
                try:
                    if not sim.wait_settled(args.arm_timeout):
                        say(armed=False, decision=sim.decision, brake=sim.brake_state)
                        return 1
                    say(armed=True)
                    run = sim.run(load_scenario(find_scenario(SCENARIO)))
                    levels = [r.cmd.level_pct for r in actuator.commands_since(
                        run.start_mono_ns) if r.t_ns <= run.end_mono_ns]
                    say(scenario=SCENARIO, passed=run.verdict.passed,
                        verdict=str(run.verdict), max_level_pct=max(levels, default=0))
                    sim.wait_settled(60)
                finally:
                    sim.stop()
        finally:
            actuator.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
