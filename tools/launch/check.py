"""`aeb up --check`: every process of a table validated exactly as it would start.

Each `aeb` service (and the router) is run with the command line, environment and
working directory the launcher would give it, plus `--check`: the service loads its
config with the same overrides, reads every file it names (calibration, replay log, Zenoh
config) and builds what it builds before touching the bus or a device, then exits 0 or
2 naming the problem. Programs started with `exec` cannot be checked beyond existing.
"""

import os
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.systemd import NOTIFY_ENV
from aeb_radar_camera.tools.launch.table import Launch

# the commands with a `--check` option
CHECKABLE = frozenset({"radar", "camera", "fusion", "brake", "vehicle", "router"})
CHECK_TIMEOUT_S = 120.0      # a cold start imports OpenCV and numpy on a loaded machine


@dataclass(frozen=True)
class CheckResult:
    name: str
    ok: bool | None          # None: not checked
    detail: str


def check_launch(launch: Launch, timeout_s: float = CHECK_TIMEOUT_S) -> CheckResult:
    """Run the launch's command with `--check`; never raises."""
    if launch.command not in CHECKABLE:
        what = f"aeb {launch.command}" if launch.command else "an exec program"
        return CheckResult(launch.name, None, f"not checked ({what} has no --check)")
    env = {k: v for k, v in os.environ.items() if k not in NOTIFY_ENV} | launch.env
    try:
        done = subprocess.run([*launch.argv, "--check"], cwd=launch.cwd, env=env,
                              stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return CheckResult(launch.name, False, f"--check did not finish in {timeout_s:.0f} s")
    except OSError as exc:
        return CheckResult(launch.name, False, f"cannot run: {exc}")
    if done.returncode == 0:
        said = done.stdout.strip().splitlines()
        return CheckResult(launch.name, True,
                           said[-1].removeprefix(f"{launch.command}: ") if said else "ok")
    lines = [ln for ln in done.stderr.strip().splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error")] or lines[-3:]
    return CheckResult(launch.name, False,
                       f"exit {done.returncode}: " + " | ".join(errors or ["(no message)"]))


def check_all(launches: list[Launch]) -> list[CheckResult]:
    """Every launch checked, in parallel, results in table order."""
    with ThreadPoolExecutor(max_workers=max(1, min(4, len(launches)))) as pool:
        return list(pool.map(check_launch, launches))


def _config_of(launch: Launch) -> Path | None:
    argv = launch.argv
    return Path(argv[argv.index("--config") + 1]) if "--config" in argv[:-1] else None


def reach_warnings(launches: list[Launch]) -> list[str]:
    """Where a fusion of the table decides farther ahead than a radar of the table passes
    tracks (its prefilter's `max_range_m`): the rule never sees what lies between, so
    its stages come late at speed. As the config files say (`--set` in a service's args
    is not applied); a config that does not load is left to its own `--check`."""
    ranges: list[tuple[str, float]] = []
    for launch in launches:
        path = _config_of(launch)
        if launch.command == "radar" and path is not None:
            try:
                cfg = load_config(path, RadarConfig)
            except ConfigError:
                continue
            ranges.append((launch.name, cfg.radar.prefilter.max_range_m))
    out = []
    for launch in launches:
        path = _config_of(launch)
        if launch.command != "fusion" or path is None:
            continue
        try:
            decision = load_config(path, FusionConfig).fusion.decision
        except ConfigError:
            continue
        far = decision.range_bounds_m[1]
        out += [f"{launch.name}: its {decision.rule.value} rule decides out to {far:g} m, "
                f"but {name} passes tracks to {reach:g} m only (set [radar.prefilter] "
                f"max_range_m = {far:g} in its config)"
                for name, reach in ranges if reach < far]
    return out
