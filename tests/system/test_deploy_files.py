"""The files under deploy/: every Zenoh config is accepted by zenoh, the secure profile
works end to end (mutual TLS and access control) with certificates made by its script,
and the process tables name valid service configs (the systemd units:
test_systemd_units.py)."""

import json
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
import zenoh

from aeb_radar_camera.common.resources import DEPLOY
from tests.support import free_port, wait_for

ZENOH_CONFIGS = sorted((DEPLOY / "zenoh").rglob("*.json5"))


def test_there_are_router_client_and_secure_configs():
    names = {p.relative_to(DEPLOY / "zenoh").as_posix() for p in ZENOH_CONFIGS}
    assert {"router.json5", "client.json5", "ecu-a-router.json5", "ecu-b-router.json5",
            "secure/router.json5", "secure/client-fusion.json5"} <= names


@pytest.mark.parametrize("path", ZENOH_CONFIGS, ids=lambda p: p.name)
def test_zenoh_accepts_every_config_and_multicast_is_off(path):
    conf = zenoh.Config.from_file(str(path))
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    mode = json.loads(conf.get_json("mode"))
    assert mode in ("router", "client")
    endpoints = json.loads(conf.get_json("listen/endpoints" if mode == "router"
                                         else "connect/endpoints"))
    assert endpoints and not any("0.0.0.0" in ep or "[::]" in ep for ep in endpoints)


def test_zenoh_rejects_a_misspelt_key(tmp_path):
    # The test above means something only if from_file validates.
    bad = tmp_path / "bad.json5"
    bad.write_text('{ mode: "router", scoutin: {} }')
    with pytest.raises(zenoh.ZError, match="scoutin"):
        zenoh.Config.from_file(str(bad))


def _conf(path: Path, **values: object) -> zenoh.Config:
    conf = zenoh.Config.from_file(str(path))
    for key, value in values.items():
        conf.insert_json5(key, json.dumps(value))
    return conf


TLS = "transport/link/tls/"


def _secure_router(certs: Path, endpoint: str) -> zenoh.Session:
    """The shipped secure router on `endpoint`, with the certificates in `certs`."""
    return zenoh.open(_conf(DEPLOY / "zenoh/secure/router.json5", **{
        "listen/endpoints": [endpoint],
        TLS + "root_ca_certificate": str(certs / "ca.pem"),
        TLS + "listen_certificate": str(certs / "router.pem"),
        TLS + "listen_private_key": str(certs / "router-key.pem"),
    }))


def _secure_client(name: str, endpoint: str, ca: Path, cert: Path,
                   **values: object) -> zenoh.Config:
    """The shipped client file of `name`, trusting the CA in folder `ca`, presenting
    `cert` (its path without ``.pem``)."""
    return _conf(DEPLOY / f"zenoh/secure/client-{name}.json5", **{
        "connect/endpoints": [endpoint],
        TLS + "root_ca_certificate": str(ca / "ca.pem"),
        TLS + "connect_certificate": f"{cert}.pem",
        TLS + "connect_private_key": f"{cert}-key.pem",
        **values,
    })


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is not installed")
def test_secure_profile_mutual_tls_and_access_control(tmp_path):
    certs = tmp_path / "certs"
    subprocess.run(["sh", str(DEPLOY / "zenoh/secure/make-certs.sh"), str(certs)],
                   check=True, capture_output=True, timeout=120)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = _secure_router(certs, endpoint)

    def client(name: str, cert: str | None = None) -> zenoh.Session:
        return zenoh.open(_secure_client(name, endpoint, certs, certs / (cert or name)))

    sessions: list[zenoh.Session] = []
    try:
        fusion = client("fusion", "fusion-primary")
        candidate = client("fusion-candidate")
        brake, monitor, radar = (client(n) for n in ("brake", "monitor", "radar"))
        sessions += [fusion, candidate, brake, monitor, radar]
        got: list[tuple[str, str]] = []
        lock = threading.Lock()

        payloads_seen: dict[str, set[bytes]] = {"primary": set()}

        def collect(who: str):
            def cb(sample: zenoh.Sample) -> None:
                with lock:
                    got.append((who, str(sample.key_expr)))
                    if who == "brake" and str(sample.key_expr).endswith("primary/brake_cmd"):
                        payloads_seen["primary"].add(sample.payload.to_bytes())
            return cb

        brake.declare_subscriber("aeb/ego/fusion/*/brake_cmd", collect("brake"))
        # The brake may not subscribe to what is not its input: denied, receives nothing.
        brake.declare_subscriber("aeb/ego/radar/front/tracks", collect("brake"))
        monitor.declare_subscriber("aeb/ego/**", collect("monitor"))
        alive: list[str] = []
        monitor.liveliness().declare_subscriber(
            "aeb/ego/health/**", lambda s: alive.append(str(s.key_expr)), history=True)
        # Keep the tokens: a token that is garbage-collected is undeclared.
        tokens = [fusion.liveliness().declare_token("aeb/ego/health/fusion/primary"),
                  fusion.liveliness().declare_token("aeb/ego/health/brake/main")]  # not fusion's

        def flowed() -> bool:
            fusion.put("aeb/ego/fusion/primary/brake_cmd", b"cmd")
            fusion.put("aeb/ego/brake/status", b"forged")          # not fusion's key
            fusion.put("aeb/ego/radar/front/status", b"forged")    # not fusion's key
            fusion.put("aeb/ego/camera/front/jpeg", b"forged")     # only the camera's
            radar.put("aeb/ego/radar/front/tracks", b"tracks")     # the radar's own key
            # the candidate holds a fusion certificate, but not the primary's
            candidate.put("aeb/ego/fusion/primary/brake_cmd", b"forged")
            candidate.put("aeb/ego/fusion/candidate/brake_cmd", b"shadow")  # its own
            with lock:
                return {("brake", "aeb/ego/fusion/primary/brake_cmd"),
                        ("brake", "aeb/ego/fusion/candidate/brake_cmd"),
                        ("monitor", "aeb/ego/radar/front/tracks")} <= set(got)

        wait_for(flowed, 60, 0.1, "brake command through the secure router")
        wait_for(lambda: "aeb/ego/health/fusion/primary" in alive, 30, 0.05, "token")
        time.sleep(0.5)  # negative check: let any wrongly admitted sample arrive
        with lock:
            # The brake's radar subscription was refused: the tracks reach the monitor only.
            assert set(got) == {("brake", "aeb/ego/fusion/primary/brake_cmd"),
                                ("brake", "aeb/ego/fusion/candidate/brake_cmd"),
                                ("monitor", "aeb/ego/fusion/primary/brake_cmd"),
                                ("monitor", "aeb/ego/fusion/candidate/brake_cmd"),
                                ("monitor", "aeb/ego/radar/front/tracks")}
            # what reached the brake on the primary's key came from the primary only
            primary = [k for w, k in got if w == "brake" and k.endswith("primary/brake_cmd")]
            assert primary and payloads_seen["primary"] == {b"cmd"}
        assert set(alive) == {"aeb/ego/health/fusion/primary"}
        del tokens
    finally:
        for s in sessions:
            s.close()
        router.close()


TABLES = ["single-host", "ecu-a", "ecu-b"]


def _config_types() -> dict[str, type]:
    from aeb_radar_camera.common.config.brake import BrakeConfig
    from aeb_radar_camera.common.config.camera import CameraConfig
    from aeb_radar_camera.common.config.fusion import FusionConfig
    from aeb_radar_camera.common.config.radar import RadarConfig
    from aeb_radar_camera.common.config.vehicle import VehicleConfig

    return {"radar": RadarConfig, "camera": CameraConfig, "fusion": FusionConfig,
            "brake": BrakeConfig, "vehicle": VehicleConfig}


@pytest.mark.parametrize("name", TABLES)
def test_shipped_process_tables_resolve_to_valid_service_configs(name):
    from aeb_radar_camera.common.config.loader import load_config
    from aeb_radar_camera.tools.launch.table import load_table, resolve_launches

    path = DEPLOY / f"{name}.toml"
    table, workdir = load_table(path)
    launches = resolve_launches(table, workdir, str(path))
    assert launches[0].name == "router"
    types = _config_types()
    for entry in table.service:    # enabled or not: every config a table names must load
        assert entry.aeb in types, entry
        assert entry.config, f"{name}: {entry.name} has no config"
        load_config(workdir / entry.config, types[entry.aeb])
    services = {launch.name for launch in launches[1:]}
    expected = {"single-host": {"radar", "camera", "fusion", "brake"},
                "ecu-a": {"radar", "camera", "brake"}, "ecu-b": {"fusion"}}[name]
    assert services == expected


def test_the_two_boards_meet_at_ecu_a_and_brake_ages_commands_on_wall_clocks():
    import tomllib

    from aeb_radar_camera.common.config.brake import BrakeConfig
    from aeb_radar_camera.common.config.loader import load_config

    a = zenoh.Config.from_file(str(DEPLOY / "zenoh/ecu-a-router.json5"))
    b = zenoh.Config.from_file(str(DEPLOY / "zenoh/ecu-b-router.json5"))
    a_listen = set(json.loads(a.get_json("listen/endpoints")))
    b_connect = set(json.loads(b.get_json("connect/endpoints")))
    assert b_connect and b_connect <= a_listen
    table = tomllib.loads((DEPLOY / "ecu-a.toml").read_text())
    brake = next(s for s in table["service"] if s["name"] == "brake")
    assert load_config(DEPLOY / brake["config"], BrakeConfig).brake.age_clock.value \
        == "wall"


@pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is not installed")
def test_secure_router_refuses_a_client_without_a_certificate_of_its_ca(tmp_path):
    """A process with a certificate of another CA gets no session at all."""
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    for folder in (ours, theirs):
        subprocess.run(["sh", str(DEPLOY / "zenoh/secure/make-certs.sh"), str(folder)],
                       check=True, capture_output=True, timeout=120)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = _secure_router(ours, endpoint)
    try:
        for name in ("fusion-primary", "brake"):
            conf = _secure_client("brake", endpoint, ours, theirs / name,
                                  **{"connect/timeout_ms": 3000, "connect/exit_on_failure": True})
            with pytest.raises(zenoh.ZError):
                zenoh.open(conf).close()
        # the same client with our CA's certificate connects: the refusal was the identity
        zenoh.open(_secure_client("brake", endpoint, ours, ours / "brake", **{
            "connect/timeout_ms": 10000, "connect/exit_on_failure": True})).close()
    finally:
        router.close()
