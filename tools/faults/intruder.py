"""A SIMULATED attacker on the vehicle network: publishes BrakeCommands on the brake's
key as a process without the fusion instance's command key would (docs/security.md).

    python -m aeb_radar_camera.tools.faults.intruder --connect tcp/127.0.0.1:7447 \
        [--instance primary]
        [--attacks ahead,jump,forged,replay,flood] [--flood-s 1.0] [--flood-hz 1000]
        [--zenoh-config FILE]

Attacks, in this order (each is counted in what it prints as one JSON line at the end):

- `ahead`: valid-looking unsigned BRAKE 100 % commands with sequence numbers ahead of the
  real fusion's (the last one seen + 1, + 10, + 1000);
- `jump`: sequence 2**62 and 2**64 - 1, unsigned and with a forged MAC;
- `forged`: the real fusion's key id with a MAC made with a guessed key;
- `replay`: the real fusion's own commands, recorded from the bus for `--record-s`, then
  published again, byte for byte, once they are older than the brake's `max_age_ms`;
- `flood`: unsigned and forged commands at `--flood-hz` (0: as fast as Zenoh takes
  them) for `--flood-s`. An unbounded flood is a denial of service that no check in the
  brake can stop on the default profile (docs/security.md).

With `--key FILE` (a stolen or published command key of the instance), two more attacks,
not in the default list:

- `keyed-ahead`: for `--keyed-s`, after every real command seen, a BRAKE 100 % command
  at its sequence number + 2 signed with the key in the real fusion's own session (read
  from the bus): what the published example key allowed before the brake refused it on
  a real actuator;
- `keyed-flood`: commands signed with the key in a session of its own at `--flood-hz`
  for `--flood-s` (a second sender of the key, or a flood on the brake's own key).

`--blind`: for an intruder that may not subscribe to the brake's key (the secure
profile's access control): no recording, no replay; the sequence numbers ahead are
guessed (from 1,000,000).

Exit code 0 once every attack was published; 1 when the bus cannot be opened or (not
blind) no command of the real fusion was seen in 30 s.
"""

import argparse
import json
import secrets
import sys
import threading
import time
from collections.abc import Callable

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandKey, CommandSigner, KeyFileError, load_key
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    Decision,
    DecodeError,
    Header,
    VerifierStatus,
    decode,
)

ATTACKS = ("ahead", "jump", "forged", "replay", "flood")
KEYED_ATTACKS = ("keyed-ahead", "keyed-flood")


def forged_command(seq: int, instance: str, level: float = 100.0) -> BrakeCommand:
    """A well-formed BRAKE command stamped now, without authentication."""
    now = mono_ns()
    return BrakeCommand(
        header=Header(seq=seq, source=f"fusion/{instance}", stamp_ns=wall_ns(),
                      pub_mono_ns=now),
        instance=instance, decision=Decision.BRAKE, brake_level_pct=level,
        verifier_status=VerifierStatus.OK, held=False, track_id=1, range_m=5.0, ttc_s=0.5,
        reason="intruder", radar_seq=seq, radar_last_frame_mono_ns=now)


class Recorder:
    """The real fusion's raw payloads as they pass, and its last sequence number."""

    def __init__(self) -> None:
        self.payloads: list[bytes] = []
        self.last_seq = -1
        self.key_id = ""
        self.session: int | None = None     # the real fusion's CommandAuth.session
        self.changed = threading.Condition()
        self.recording = True
        self._lock = threading.Lock()
        self.seen = threading.Event()

    def __call__(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        try:
            cmd = decode(payload, BrakeCommand)
        except DecodeError:
            return
        if cmd.reason == "intruder":
            return
        with self._lock:
            if cmd.auth is not None and not self.key_id:
                self.key_id = cmd.auth.key_id
            if cmd.auth is not None:
                self.session = cmd.auth.session
            self.last_seq = max(self.last_seq, cmd.header.seq)
            if self.recording:
                self.payloads.append(payload)
        with self.changed:
            self.changed.notify_all()
        self.seen.set()


def run(bus: Bus, instance: str, attacks: tuple[str, ...], record_s: float,
        replay_delay_s: float, flood_s: float, flood_hz: float = 1000.0, blind: bool = False,
        progress: Callable[[str], None] = lambda s: None, key: CommandKey | None = None,
        keyed_s: float = 1.0) -> dict[str, int]:
    """Publish the attacks; returns how many commands each one published. Raises
    TimeoutError when (not `blind`) no command of the instance is seen in 30 s,
    ValueError for a keyed attack without `key`."""
    if key is None and set(attacks) & set(KEYED_ATTACKS):
        raise ValueError(f"{', '.join(KEYED_ATTACKS)} need a key (--key)")
    pub = bus.publisher(FUSION_BRAKE_CMD, instance=instance)
    rec = Recorder()
    sub = None if blind else bus.subscribe_raw(FUSION_BRAKE_CMD, rec, instance=instance)
    sent: dict[str, int] = {a: 0 for a in attacks}
    try:
        if blind:
            rec.last_seq = 1_000_000
        elif not rec.seen.wait(30.0):
            raise TimeoutError(f"no command of fusion/{instance} seen in 30 s")
        else:
            time.sleep(record_s)        # the recording's length (what the replay repeats)
        rec.recording = False
        guessed = CommandSigner(CommandKey(rec.key_id or f"{instance}-guess", instance,
                                           secrets.token_bytes(32)))

        def put(cmd: BrakeCommand, attack: str, sign: bool) -> None:
            pub.put_bytes(guessed.sign(cmd)) if sign else pub.put(cmd)
            sent[attack] += 1

        if "ahead" in attacks:
            progress("ahead")
            for ahead in (1, 10, 1000):
                put(forged_command(rec.last_seq + ahead, instance), "ahead", False)
        if "jump" in attacks:
            progress("jump")
            for seq in (2**62, 2**64 - 1):
                put(forged_command(seq, instance), "jump", False)
                put(forged_command(seq, instance), "jump", True)
        if "forged" in attacks:
            progress("forged")
            for ahead in (1, 2, 3):
                put(forged_command(rec.last_seq + ahead, instance), "forged", True)
        if "replay" in attacks:
            progress(f"replay of {len(rec.payloads)} recorded commands")
            time.sleep(replay_delay_s)  # older than the brake accepts: a replay, not a relay
            for payload in rec.payloads:
                pub.put_bytes(payload)
                sent["replay"] += 1
        if "flood" in attacks:
            progress("flood")
            start = time.monotonic()
            end = start + flood_s
            while (now := time.monotonic()) < end:
                if flood_hz > 0 and sent["flood"] >= (now - start) * flood_hz:
                    time.sleep(min(0.001, end - now))   # the attacker's own pacing
                    continue
                seq = rec.last_seq + 1 + sent["flood"] % 50
                put(forged_command(seq, instance), "flood", sent["flood"] % 2 == 1)
        if "keyed-ahead" in attacks and key is not None:
            progress("keyed-ahead")
            stolen = CommandSigner(key, session=rec.session)
            end = time.monotonic() + keyed_s
            last = -1
            while time.monotonic() < end:
                with rec.changed:
                    rec.changed.wait_for(lambda last=last: rec.last_seq != last,  # type: ignore[misc]
                                         timeout=0.1)
                if rec.last_seq == last:
                    continue
                last = rec.last_seq
                pub.put_bytes(stolen.sign(forged_command(last + 2, instance)))
                sent["keyed-ahead"] += 1
        if "keyed-flood" in attacks and key is not None:
            progress("keyed-flood")
            own = CommandSigner(key)
            start = time.monotonic()
            end = start + flood_s
            while (now := time.monotonic()) < end:
                if flood_hz > 0 and sent["keyed-flood"] >= (now - start) * flood_hz:
                    time.sleep(min(0.0005, end - now))
                    continue
                pub.put_bytes(own.sign(forged_command(sent["keyed-flood"], instance)))
                sent["keyed-flood"] += 1
    finally:
        if sub is not None:
            sub.undeclare()
        pub.undeclare()
    return sent


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeb_radar_camera.tools.faults.intruder", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--connect", action="append", default=[])
    parser.add_argument("--zenoh-config", default="", help="Zenoh JSON5 (e.g. a TLS client)")
    parser.add_argument("--vehicle", default="ego")
    parser.add_argument("--instance", default="primary", help="the instance to impersonate")
    parser.add_argument("--attacks", default=",".join(ATTACKS))
    parser.add_argument("--record-s", type=float, default=0.5)
    parser.add_argument("--replay-delay-s", type=float, default=0.5)
    parser.add_argument("--flood-s", type=float, default=1.0)
    parser.add_argument("--flood-hz", type=float, default=1000.0, help="0: unbounded")
    parser.add_argument("--key", help="a command key file of the instance (keyed attacks)")
    parser.add_argument("--keyed-s", type=float, default=1.0,
                        help="how long keyed-ahead follows the real stream")
    parser.add_argument("--blind", action="store_true",
                        help="do not subscribe (no replay, guessed sequence numbers)")
    args = parser.parse_args(argv)
    attacks = tuple(a for a in args.attacks.split(",") if a)
    unknown = set(attacks) - set(ATTACKS) - set(KEYED_ATTACKS)
    if unknown:
        print(f"error: unknown attacks {sorted(unknown)}; known: "
              f"{','.join(ATTACKS + KEYED_ATTACKS)}", file=sys.stderr)
        return 2
    try:
        key = load_key(args.key) if args.key else None
    except KeyFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if key is None and set(attacks) & set(KEYED_ATTACKS):
        print("error: keyed attacks need --key", file=sys.stderr)
        return 2
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=tuple(args.connect),
                             config_file=args.zenoh_config)
    try:
        with Bus.open(settings, args.vehicle, "intruder") as bus:
            sent = run(bus, args.instance, attacks, args.record_s, args.replay_delay_s,
                       args.flood_s, args.flood_hz, args.blind,
                       lambda s: print(f"intruder: {s}", flush=True), key, args.keyed_s)
    except (BusError, TimeoutError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps({"sent": sent}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

