"""The systemd units (deploy/systemd): `systemd-analyze verify` clean where systemd is
installed, and, everywhere, each unit parsed and checked key by key: Type=notify with a
watchdog, no restart on exit code 2, and an ExecStart that resolves, through the board's
process table, to the process and per-ECU config that board runs."""

import shutil
import subprocess
from pathlib import Path

import pytest

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.init import UNIT_AEB, UNIT_CONFIGS
from aeb_radar_camera.tools.init import main as init
from aeb_radar_camera.tools.launch.main import parse_args
from aeb_radar_camera.tools.launch.table import load_table, resolve_launches

UNITS = sorted((DEPLOY / "systemd").glob("*.service"))
TABLES = ["single-host", "ecu-a", "ecu-b"]
# The keys the units may use, per section (systemd.unit(5), .service(5), .exec(5),
# .kill(5)): what `systemd-analyze verify` would call unknown, where it cannot run.
KNOWN = {
    "Unit": {"Description", "Wants", "After", "Requires", "PartOf", "Before"},
    "Service": {"Type", "NotifyAccess", "WatchdogSec", "TimeoutStartSec", "TimeoutStopSec",
                "User", "Group", "SupplementaryGroups", "Environment", "EnvironmentFile",
                "WorkingDirectory", "LimitRTPRIO", "ExecStart", "Restart", "RestartSec",
                "RestartPreventExitStatus", "KillMode", "KillSignal"},
    "Install": {"WantedBy"},
}


def parse_unit(path: Path) -> dict[str, dict[str, list[str]]]:
    """Sections -> key -> every value in order (Environment= may repeat). Raises
    ValueError on a line that is neither a comment, a section nor `Key=Value`."""
    sections: dict[str, dict[str, list[str]]] = {}
    current: dict[str, list[str]] | None = None
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], {})
        elif "=" in line and current is not None:
            key, value = line.split("=", 1)
            current.setdefault(key.strip(), []).append(value.strip())
        else:
            raise ValueError(f"{path.name}:{n}: not Key=Value: {raw!r}")
    return sections


def seconds(value: str) -> float:
    units = {"ms": 0.001, "s": 1.0, "min": 60.0}
    for suffix, scale in units.items():
        if value.endswith(suffix) and value[: -len(suffix)].replace(".", "").isdigit():
            return float(value[: -len(suffix)]) * scale
    return float(value)


def in_deploy(path: str) -> Path:
    """A path of the units (`aeb init /etc/aeb`) in the shipped deploy/."""
    assert path.startswith(UNIT_CONFIGS + "/"), path
    return DEPLOY / path.removeprefix(UNIT_CONFIGS + "/")


def test_there_are_the_three_units():
    assert [u.name for u in UNITS] == ["aeb-router.service", "aeb-up@.service", "aeb@.service"]


@pytest.mark.parametrize("unit", UNITS, ids=lambda p: p.name)
def test_every_key_is_known_and_the_unit_notifies_with_a_watchdog(unit):
    sections = parse_unit(unit)
    assert set(sections) == set(KNOWN)
    for name, keys in sections.items():
        assert set(keys) <= KNOWN[name], f"{unit.name} [{name}]: {set(keys) - KNOWN[name]}"
    service = {k: v[-1] for k, v in sections["Service"].items()}
    assert service["Type"] == "notify"
    assert service["NotifyAccess"] == "main"      # the process exec'd into, not children
    assert 2.0 <= seconds(service["WatchdogSec"]) <= 30.0
    assert "2" in service["RestartPreventExitStatus"].split()
    assert service["Restart"] in ("always", "on-failure")
    assert service["ExecStart"].split()[0] == UNIT_AEB


def unit_env(unit: Path, board_env: str | None) -> dict[str, str]:
    """The environment systemd gives the unit: Environment=, then the EnvironmentFile."""
    service = parse_unit(unit)["Service"]
    env = dict(v.partition("=")[::2] for v in service.get("Environment", []))
    for ref in service.get("EnvironmentFile", []):
        assert ref.startswith("-"), "a missing board.env must not stop the unit"
        assert in_deploy(ref[1:]) == DEPLOY / "board.env"
        if board_env is not None:
            env.update(line.partition("=")[::2] for line in board_env.splitlines()
                       if line and not line.startswith("#"))
    return env


def exec_args(unit: Path, env: dict[str, str], instance: str) -> list[str]:
    words = parse_unit(unit)["Service"]["ExecStart"][-1].split()[1:]
    out = []
    for w in words:
        for key, value in env.items():
            w = w.replace("${" + key + "}", value)
        out.append(w.replace("%i", instance))
    return out


def resolved(args: list[str]) -> dict[str, tuple[str, ...]]:
    """What `aeb up ... --exec NAME` would exec, per process name."""
    assert args[0] == "up"
    ns = parse_args(args[1:])
    table_path = in_deploy(ns.table)
    table, workdir = load_table(table_path)
    return {launch.name: launch.argv for launch in resolve_launches(table, workdir,
                                                                    str(table_path))}


def test_without_a_board_env_the_units_run_the_single_host_table():
    env = unit_env(DEPLOY / "systemd/aeb-router.service", None)
    assert in_deploy(env["AEB_TABLE"]) == DEPLOY / "single-host.toml"
    assert in_deploy(unit_env(DEPLOY / "systemd/aeb-router.service",
                              (DEPLOY / "board.env").read_text())["AEB_TABLE"]) \
        == DEPLOY / "single-host.toml"


@pytest.mark.parametrize("board", TABLES)
def test_each_boards_router_and_services_resolve_from_its_table(board):
    board_env = f"AEB_TABLE={UNIT_CONFIGS}/{board}.toml\n"
    router = DEPLOY / "systemd/aeb-router.service"
    args = exec_args(router, unit_env(router, board_env), "")
    assert args[-2:] == ["--exec", "router"]
    launches = resolved(args)
    table, _ = load_table(DEPLOY / f"{board}.toml")
    assert "--config-file" in launches["router"]
    assert launches["router"][launches["router"].index("--config-file") + 1] == \
        str(DEPLOY / table.router.config)
    service = DEPLOY / "systemd/aeb@.service"
    for entry in (s for s in table.service if s.enabled):
        args = exec_args(service, unit_env(service, board_env), entry.name)
        argv = resolved(args)[args[-1]]
        assert argv[argv.index("--config") + 1] == str(DEPLOY / entry.config)


def test_ecu_as_brake_unit_runs_ecu_as_own_brake_config():
    board_env = f"AEB_TABLE={UNIT_CONFIGS}/ecu-a.toml\n"
    service = DEPLOY / "systemd/aeb@.service"
    args = exec_args(service, unit_env(service, board_env), "brake")
    argv = resolved(args)["brake"]
    assert argv[argv.index("--config") + 1] == str(DEPLOY / "ecu-a/brake.toml")


@pytest.mark.parametrize("board", TABLES)
def test_aeb_up_units_name_a_shipped_table(board):
    unit = DEPLOY / "systemd/aeb-up@.service"
    args = exec_args(unit, unit_env(unit, None), board)
    assert "--exec" not in args
    assert set(resolved(args)) >= {"router"}


# -- systemd-analyze verify -----------------------------------------------------------

ANALYZE = shutil.which("systemd-analyze")
needs_analyze = pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze is not "
                                   "installed; the key-by-key tests above cover the units")


def verify(folder: Path, *units: str) -> subprocess.CompletedProcess[str]:
    assert ANALYZE is not None
    return subprocess.run([ANALYZE, "verify", *units], cwd=folder, capture_output=True,
                          text=True, timeout=120)


@pytest.fixture
def installed_units(tmp_path, capsys):
    """The units as `aeb init` writes them: this installation's aeb, the copy's tables."""
    assert init([str(tmp_path / "aeb")]) == 0
    capsys.readouterr()
    return tmp_path / "aeb" / "systemd"


@needs_analyze
def test_systemd_analyze_verify_is_clean(installed_units):
    units = ["aeb-router.service", *(f"aeb@{s}.service" for s in
                                     ("radar", "camera", "fusion", "brake", "vehicle")),
             *(f"aeb-up@{t}.service" for t in TABLES)]
    done = verify(installed_units, *units)
    assert done.returncode == 0, done.stderr
    assert (done.stdout + done.stderr).strip() == ""


@needs_analyze
def test_systemd_analyze_verify_would_see_a_mistake(installed_units):
    # the clean result above means something only if verify reports what is wrong
    bad = installed_units / "aeb@.service"
    bad.write_text(bad.read_text().replace("WatchdogSec=", "WatchdogSecs=")
                   .replace("Type=notify", "Type=notified"))
    done = verify(installed_units, "aeb@brake.service")
    said = done.stdout + done.stderr
    assert "Unknown key 'WatchdogSecs'" in said and "notified" in said
