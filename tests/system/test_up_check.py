"""`aeb up --check` validates every process of a table as the process itself would at
start (its own `--check`, with the launcher's command line), and `aeb up --exec` runs one
of them in place of the launcher."""

import os
import subprocess
import sys

import pytest

from aeb_radar_camera.common.command_auth import new_key, write_key
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION, EXAMPLE_KEYS
from aeb_radar_camera.tools.launch.main import main as up

TABLE_HEAD = """
[router]
listen = ["tcp/127.0.0.1:{port}"]
[zenoh]
connect = ["tcp/127.0.0.1:{port}"]
"""


def write_table(folder, services: str, port: int = 1) -> str:
    path = folder / "table.toml"
    path.write_text(TABLE_HEAD.format(port=port) + services)
    return str(path)


def service(name: str, command: str, config: str, args: str = "") -> str:
    return (f'[[service]]\nname = "{name}"\naeb = "{command}"\nconfig = "{config}"\n'
            + (f"args = {args}\n" if args else ""))


@pytest.fixture
def configs(tmp_path):
    write_key(tmp_path / "primary.key", new_key("primary"))
    (tmp_path / "brake.toml").write_text(
        '[brake]\ndeadline_ms = 200.0\ncommand_keys = ["primary.key"]\n')
    (tmp_path / "fusion.toml").write_text(f'[fusion]\ncalibration = "{EXAMPLE_CALIBRATION}"\n')
    return tmp_path


def test_a_valid_table_passes_and_nothing_is_started(configs, capsys):
    # no router listens on port 1: --check must not need the bus
    table = write_table(configs, service("brake", "brake", "brake.toml")
                        + service("fusion", "fusion", "fusion.toml"))
    assert up(["--check", "--table", table]) == 0
    out = capsys.readouterr().out
    for name in ("router", "brake", "fusion"):
        assert f"ok      {name}: " in out
    assert "brake: configuration ok" in out and "--connect tcp/127.0.0.1:1" in out


def example_key_brake(folder, extra: str = "") -> str:
    (folder / "brake.toml").write_text(
        f'[brake]\ncommand_keys = ["{EXAMPLE_KEYS / "primary.key"}"]\n{extra}'
        '[brake.serial]\nport = "/dev/ttyACM0"\n')
    return write_table(folder, service("brake", "brake", "brake.toml"))


def test_the_published_example_key_on_a_real_actuator_is_refused(tmp_path, capsys):
    assert up(["--check", "--table", example_key_brake(tmp_path)]) == 2
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if " brake: " in ln)
    assert line.split()[0] == "INVALID" and "INSECURE EXAMPLE KEY" in line
    assert "allow_example_key" in line


def test_the_example_key_opt_in_is_said_loudly_not_configuration_ok(tmp_path, capsys):
    table = example_key_brake(tmp_path, "allow_example_key = true\n")
    assert up(["--check", "--table", table]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if " brake: " in ln)
    assert line.split()[0] == "WARNING" and "REAL actuator /dev/ttyACM0" in line
    assert "configuration ok" not in line


def test_a_key_file_readable_by_others_is_refused_naming_file_and_mode(configs, capsys):
    (configs / "primary.key").chmod(0o644)
    assert up(["--check", "--table", write_table(
        configs, service("brake", "brake", "brake.toml"))]) == 2
    out = capsys.readouterr().out
    assert "INVALID brake" in out and "primary.key: mode 0644" in out


# Each config below loads as a file of the right shape, which is all --check looked at
# before: the services themselves reject it at start.
@pytest.mark.parametrize(("files", "entry", "named"), [
    ({"fusion.toml": '[fusion]\ncalibration = "missing.toml"\n'},
     service("fusion", "fusion", "fusion.toml"), "missing.toml"),
    ({"brake.toml": "[brake]\ndeadline_ms = -1.0\n"},
     service("brake", "brake", "brake.toml"), "deadline_ms"),
    ({"brake.toml": "[brake]\n"}, service("brake", "brake", "brake.toml"), "command_keys"),
    ({"fusion.toml": ""}, service("fusion", "fusion", "fusion.toml", '["--instance", "a/b"]'),
     "instance"),
    ({"radar.toml": '[radar.can]\ninterface = "replay"\n[radar.replay]\nfile = "drive.log"\n'},
     service("radar", "radar", "radar.toml"), "drive.log"),
    ({"camera.toml": f'[camera]\ncalibration = "{EXAMPLE_CALIBRATION}"\n'
                     '[camera.source]\nkind = "synthetic"\nfactory = "no_such.module:make"\n'},
     service("camera", "camera", "camera.toml"), "no_such"),
    ({"camera.toml": '[camera]\ncalibration = "cal.toml"\n'},
     service("camera", "camera", "camera.toml"), "cal.toml"),
    ({"fusion.toml": '[fusion.verifier]\nname = "edge_density"\nparams = { tau = "high" }\n'},
     service("fusion", "fusion", "fusion.toml"), "tau"),
    # these crashed the service only once it ran (an OverflowError, a refused Zenoh key)
    ({"brake.toml": "[brake]\ndeadline_ms = inf\n"},
     service("brake", "brake", "brake.toml"), "deadline_ms"),
    ({"fusion.toml": "[fusion.frames]\nmax_skew_s = inf\n"},
     service("fusion", "fusion", "fusion.toml"), "max_skew_s"),
    ({"brake.toml": "[brake]\ndeadline_ms = 100.0\nmax_age_ms = 150.0\n"},
     service("brake", "brake", "brake.toml"), "max_age_ms"),
    ({"radar.toml": '[zenoh.overrides]\n"scoutin/x" = 1\n'},
     service("radar", "radar", "radar.toml"), "scoutin"),
])
def test_a_config_its_service_rejects_fails_the_check(tmp_path, capsys, files, entry, named):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert up(["--check", "--table", write_table(tmp_path, entry)]) == 2
    out, err = capsys.readouterr()
    invalid = [line for line in out.splitlines() if line.strip().startswith("INVALID")]
    assert len(invalid) == 1 and named in invalid[0], out
    assert "1 of 2 processes reject their configuration" in err


def test_a_bad_router_config_fails_the_check(tmp_path, capsys):
    (tmp_path / "router.json5").write_text('{ mode: "router", scoutin: {} }')
    (tmp_path / "table.toml").write_text('[router]\nconfig = "router.json5"\n')
    assert up(["--check", "--table", str(tmp_path / "table.toml")]) == 2
    assert "scoutin" in capsys.readouterr().out


def test_programs_that_are_not_aeb_services_are_listed_as_not_checked(configs, capsys):
    table = write_table(configs, '[[service]]\nname = "logger"\nexec = ["true"]\n')
    assert up(["--check", "--table", table]) == 0
    assert "--      logger: not checked (an exec program has no --check)" in \
        capsys.readouterr().out


def test_the_shipped_board_tables_check(capsys):
    # ECU B (fusion) needs no hardware package; the tables with a RealSense camera check
    # only where pyrealsense2 is installed, and say so otherwise. ECU A's brake drives a
    # real actuator with the shipped (published) example key: refused until `aeb init`
    # or `aeb keygen` gives it a key of its own
    assert up(["--check", "--table", str(DEPLOY / "ecu-b.toml")]) == 0
    capsys.readouterr()
    assert up(["--check", "--table", str(DEPLOY / "ecu-a.toml")]) == 2
    out = capsys.readouterr().out
    assert "INVALID brake: exit 2: error: brake.command_keys: primary-insecure-example" in out
    assert "ok      radar:" in out
    try:
        import pyrealsense2  # noqa: F401
    except ImportError:
        assert "INVALID camera: exit 2: error: the realsense source needs pyrealsense2" in out


def test_exec_replaces_the_launcher_with_the_process(tmp_path):
    probe = ("import os, sys; print(os.getpid(), os.getcwd(), os.environ['AEB_PROBE'], "
             "sys.argv[1:])")
    (tmp_path / "run").mkdir()
    (tmp_path / "table.toml").write_text(
        'workdir = "run"\n[[service]]\nname = "probe"\n'
        f'exec = ["{sys.executable}", "-c", "{probe}", "x"]\nenv = {{ AEB_PROBE = "yes" }}\n')
    proc = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.tools.cli", "up", "--table",
                             str(tmp_path / "table.toml"), "--exec", "probe"],
                            stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0
    pid, cwd, probe_env, argv = out.split(" ", 3)
    assert int(pid) == proc.pid                 # the same process: systemd's main PID
    assert (cwd, probe_env, argv.strip()) == (str(tmp_path / "run"), "yes", "['x']")


def test_exec_of_an_unknown_name_is_a_clear_error(configs, capsys):
    table = write_table(configs, service("brake", "brake", "brake.toml"))
    assert up(["--exec", "radar", "--table", table]) == 2
    assert "no process 'radar' to exec; the table has router, brake" in capsys.readouterr().err


def test_services_check_without_a_router(configs):
    # --check of a service alone: no bus, no device, immediate
    env = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}
    done = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.cli", "fusion", "--config",
                           str(configs / "fusion.toml"), "--connect", "tcp/127.0.0.1:1",
                           "--check"], capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    assert "fusion: configuration ok" in done.stdout


def test_a_radar_that_passes_tracks_short_of_the_fusion_rules_reach_is_said(configs, capsys):
    from aeb_radar_camera.tools.launch.check import reach_warnings
    from aeb_radar_camera.tools.launch.table import load_table, resolve_launches

    (configs / "radar.toml").write_text('[radar.prefilter]\nmax_range_m = 25.0\n')
    (configs / "kinematic.toml").write_text(
        f'[fusion]\ncalibration = "{EXAMPLE_CALIBRATION}"\n[fusion.decision]\n'
        'rule = "kinematic"\n')
    table = write_table(configs, service("radar", "radar", "radar.toml")
                        + service("fusion", "fusion", "kinematic.toml")
                        + service("paper", "fusion", "fusion.toml"))
    launches = resolve_launches(*load_table(table), "test")
    (said,) = reach_warnings(launches)       # the paper's rule decides within 25 m
    assert said == ("fusion: its kinematic rule decides out to 80 m, but radar passes tracks "
                    "to 25 m only (set [radar.prefilter] max_range_m = 80 in its config)")
    up(["--check", "--table", table])
    assert f"WARNING {said}" in capsys.readouterr().out
    (configs / "radar.toml").write_text('[radar.prefilter]\nmax_range_m = 80.0\n')
    assert reach_warnings(launches) == []
    # the shipped single-host table's pair agrees
    assert reach_warnings(resolve_launches(*load_table(DEPLOY / "single-host.toml"),
                                           "test")) == []
