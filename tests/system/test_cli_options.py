"""Options every `aeb` command shares: `aeb --version`, and `--log-level` on every
command, an invalid level being a clear argparse error (exit 2), never a traceback."""

import importlib.metadata
import subprocess
import sys

import pytest

from aeb_radar_camera.tools.cli import main
from aeb_radar_camera.tools.commands import COMMANDS
from aeb_radar_camera.tools.launch.table import load_table, resolve_launches


def test_version_is_the_installed_distributions():
    out = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.cli", "--version"],
                         capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0
    assert importlib.metadata.version("aeb-radar-camera") in out.stdout


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_takes_a_log_level(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "--log-level" in capsys.readouterr().out


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_invalid_level_is_a_clear_error(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--log-level", "LOUD"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --log-level: invalid level 'LOUD'" in err
    assert "DEBUG, INFO, WARNING, ERROR" in err


def test_levels_are_case_insensitive_and_up_passes_its_level_to_every_aeb_child(tmp_path):
    (tmp_path / "svc.toml").write_text("")
    (tmp_path / "table.toml").write_text(
        '[[service]]\nname = "brake"\naeb = "brake"\nconfig = "svc.toml"\n'
        '[[service]]\nname = "other"\nexec = ["true"]\n')
    table, workdir = load_table(tmp_path / "table.toml")
    launches = {launch.name: launch.argv for launch in
                resolve_launches(table, workdir, "t", log_level="DEBUG")}
    for name in ("router", "brake"):
        argv = launches[name]
        assert argv[argv.index("--log-level") + 1] == "DEBUG"
    assert "--log-level" not in launches["other"]     # not an aeb command


def test_a_lower_case_level_reaches_the_service(tmp_path):
    from aeb_radar_camera.common.config.brake import BrakeConfig
    from aeb_radar_camera.common.service import load_service_config, service_argparser

    args = service_argparser("brake", "").parse_args(["--log-level", "debug"])
    assert load_service_config(args, BrakeConfig).log.level.value == "DEBUG"


@pytest.mark.parametrize(("argv", "said"), [
    (["monitor", "--interval", "-1"], "argument --interval: '-1': must be greater than 0"),
    (["monitor", "--interval", "0"], "argument --interval: '0': must be greater than 0"),
    (["monitor", "--duration", "-5"], "argument --duration: '-5': must not be negative"),
    (["hz", "radar_tracks", "--interval", "nan"], "'nan': not a finite number"),
    (["echo", "radar_tracks", "--timeout", "-1"], "argument --timeout: '-1': must not be"),
    (["record", "--connect-timeout", "soon"], "argument --connect-timeout: 'soon': not a"),
])
def test_a_period_or_duration_out_of_range_is_refused(argv, said, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert said in capsys.readouterr().err
