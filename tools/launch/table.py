"""The process table of `aeb up`: which processes run on one host (or one ECU), how they
are started and restarted. A TOML file under deploy/, validated before anything starts.

Paths in a table (`config`, `router.config`, `exec`) are relative to `workdir`, and
`workdir` is relative to the table file itself, so a table works from any current
directory. See docs/deploy.md for the format.
"""

import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import msgspec

from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.tools.commands import COMMANDS
from aeb_radar_camera.tools.launch.restart import Backoff, RestartMode

_NAME = re.compile(r"^[a-z0-9][a-z0-9_\-]*$")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|unixsock-stream|ws)/.+")
ROUTER_NAME = "router"

Seconds = Annotated[float, msgspec.Meta(gt=0)]


class RouterEntry(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A Zenoh router started first, as a child process (`aeb router`)."""

    enabled: bool = True
    listen: tuple[str, ...] = ()    # empty: the config's, else tcp/127.0.0.1:7447
    connect: tuple[str, ...] = ()   # other routers (another ECU's); added to the config's
    config: str = ""                # Zenoh JSON5 router config
    realtime_priority: Annotated[int, msgspec.Meta(ge=0, le=99)] = 0   # SCHED_FIFO, 0: off

    def __post_init__(self) -> None:
        for ep in (*self.listen, *self.connect):
            if not _ENDPOINT.match(ep):
                raise ValueError(f"router endpoint {ep!r} is not of the form 'tcp/HOST:PORT'")


class ZenohEntry(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Endpoints given to every `aeb` service as `--connect` (overriding its own config),
    so that one table decides where a host's services find their router."""

    connect: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for ep in self.connect:
            if not _ENDPOINT.match(ep):
                raise ValueError(f"zenoh.connect endpoint {ep!r} is not of the form "
                                 "'tcp/HOST:PORT'")


class ServiceEntry(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One process. Exactly one of `aeb` (an `aeb` command, run with this Python) or
    `exec` (any program and its arguments)."""

    name: str
    aeb: str = ""
    exec: tuple[str, ...] = ()
    config: str = ""                # passed as `--config PATH`
    args: tuple[str, ...] = ()      # appended to the command line
    env: dict[str, str] = msgspec.field(default_factory=dict)
    restart: RestartMode | None = None   # the table's `restart.mode` when absent
    connect: bool = True            # pass the table's zenoh.connect (aeb commands only)
    enabled: bool = True
    stop_grace_s: Seconds | None = None

    def __post_init__(self) -> None:
        if not _NAME.match(self.name) or self.name == ROUTER_NAME:
            raise ValueError(f"service name {self.name!r}: lowercase letters, digits, '_', '-'"
                             f" (and not {ROUTER_NAME!r})")
        if bool(self.aeb) == bool(self.exec):
            raise ValueError(f"service {self.name!r}: give exactly one of `aeb` or `exec`")


class RestartEntry(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    mode: RestartMode = RestartMode.ON_FAILURE
    backoff: Backoff = msgspec.field(default_factory=Backoff)


class ProcessTable(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    description: str = ""
    workdir: str = "."
    stop_grace_s: Seconds = 5.0
    # Hold a PM QoS CPU latency request (microseconds) while the table runs: no CPU idle
    # state with a longer exit latency; 0 keeps idle CPUs polling (common/cpu_latency.py,
    # docs/deploy.md). Unset: the machine's idle states as they are.
    cpu_latency_us: Annotated[int, msgspec.Meta(ge=0)] | None = None
    router: RouterEntry = msgspec.field(default_factory=RouterEntry)
    zenoh: ZenohEntry = msgspec.field(default_factory=ZenohEntry)
    restart: RestartEntry = msgspec.field(default_factory=RestartEntry)
    service: tuple[ServiceEntry, ...] = ()

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for svc in self.service:
            if svc.name in seen:
                raise ValueError(f"service name {svc.name!r} appears twice")
            seen.add(svc.name)


@dataclass(frozen=True)
class Launch:
    """A process ready to start: everything resolved to absolute paths and an argv."""

    name: str
    argv: tuple[str, ...]
    env: dict[str, str]
    cwd: Path
    restart: RestartMode
    backoff: Backoff
    stop_grace_s: float
    command: str = ""      # the `aeb` command it runs; empty for an `exec` program


def load_table(path: str | Path) -> tuple[ProcessTable, Path]:
    """Read and validate a table; returns it with its resolved workdir.

    Raises ConfigError naming the file and the field, or the missing file.
    """
    p = Path(path)
    table = load_config(p, ProcessTable, what="process table")
    workdir = (p.resolve().parent / table.workdir).resolve()
    if not workdir.is_dir():
        raise ConfigError(f"{p}: workdir {table.workdir!r} is not a directory ({workdir})")
    return table, workdir


def aeb_argv(command: str) -> tuple[str, ...]:
    """An `aeb` command run with the current interpreter (works without the venv on PATH)."""
    return (sys.executable, "-m", "aeb_radar_camera.tools.cli", command)


def _resolve(workdir: Path, rel: str) -> Path:
    path = Path(rel)
    return path if path.is_absolute() else workdir / path


def resolve_launches(
    table: ProcessTable,
    workdir: Path,
    origin: str,
    only: set[str] | None = None,
    with_router: bool = True,
    log_level: str | None = None,
) -> list[Launch]:
    """The processes to start, router first, in table order.

    `only` limits the services (the router is still started when the table has one);
    `log_level` is given to every `aeb` command (the router's included) as --log-level.
    Raises ConfigError naming an unknown service in `only`, an unknown `aeb` command or a
    missing config/program file.
    """
    names = {s.name for s in table.service}
    if only is not None and only - names:
        raise ConfigError(f"{origin}: --only names unknown services {sorted(only - names)}; "
                          f"the table has {sorted(names)}")
    launches: list[Launch] = []
    if with_router and table.router.enabled:
        argv = [*aeb_argv("router")]
        for ep in table.router.listen:
            argv += ["--listen", ep]
        for ep in table.router.connect:
            argv += ["--connect", ep]
        if table.router.config:
            cfg = _resolve(workdir, table.router.config)
            if not cfg.is_file():
                raise ConfigError(f"{origin}: router.config: file {cfg} not found")
            argv += ["--config-file", str(cfg)]
        if table.router.realtime_priority:
            argv += ["--realtime-priority", str(table.router.realtime_priority)]
        if log_level:
            argv += ["--log-level", log_level]
        launches.append(Launch(ROUTER_NAME, tuple(argv), {}, workdir, RestartMode.ALWAYS,
                               table.restart.backoff, table.stop_grace_s, "router"))
    for svc in table.service:
        if not svc.enabled or (only is not None and svc.name not in only):
            continue
        where = f"{origin}: service {svc.name!r}"
        if svc.aeb:
            if svc.aeb not in COMMANDS:
                raise ConfigError(f"{where}: unknown aeb command {svc.aeb!r}; "
                                  f"known: {', '.join(sorted(COMMANDS))}")
            argv = [*aeb_argv(svc.aeb)]
        else:
            program = svc.exec[0]
            found = shutil.which(program) if "/" not in program else None
            local = _resolve(workdir, program)
            if found is None and not local.is_file():
                raise ConfigError(f"{where}: program {program!r} not found")
            argv = [found or str(local), *svc.exec[1:]]
        if svc.config:
            cfg = _resolve(workdir, svc.config)
            if not cfg.is_file():
                raise ConfigError(f"{where}: config file {cfg} not found")
            argv += ["--config", str(cfg)]
        if svc.aeb and svc.connect:
            for ep in table.zenoh.connect:
                argv += ["--connect", ep]
        if svc.aeb and log_level:
            argv += ["--log-level", log_level]
        argv += list(svc.args)
        launches.append(Launch(
            svc.name, tuple(argv), dict(svc.env), workdir,
            svc.restart or table.restart.mode, table.restart.backoff,
            svc.stop_grace_s or table.stop_grace_s, svc.aeb,
        ))
    return launches
