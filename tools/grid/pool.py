"""Many lockstep runs in parallel processes, with progress.

    cases = [Case(scenario, DEPLOY / "fusion.toml") for scenario in scenarios]
    for outcome in run_cases(cases, workers=2, progress=print_progress()):
        ...                       # in the order the cases were given

Each worker process builds the simulated camera's renderer once and keeps each
configuration it loaded; every case is one `run_scenario`, as deterministic in a worker
as in the caller's process. A case that cannot run (a bad configuration, the stack never
arming) is an outcome with its error, not the end of the others. Workers ignore SIGINT:
the caller decides (`stop`), and they finish their case and exit.
"""

import multiprocessing
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.grid.camera import SceneCamera
from aeb_radar_camera.tools.grid.lockstep import LockstepResult, LoopConfig, run_scenario
from aeb_radar_camera.tools.sim.scenario import Scenario


@dataclass(frozen=True)
class Case:
    """One run: a scenario, the followed fusion config (and a candidate in shadow mode),
    the loop's seed; `name` is how progress and results call it (default: the
    scenario's name); `plot`: where the worker writes the run's timeline plot (as `aeb
    demo` draws it), None for none."""

    scenario: Scenario
    fusion_config: Path
    candidate_config: Path | None = None
    loop_seed: int = 0
    name: str = ""
    plot: Path | None = None
    ideal: bool = False         # the IDEAL decision on this loop (lockstep.LoopConfig)

    @property
    def label(self) -> str:
        return self.name or self.scenario.name


@dataclass
class Outcome:
    """A case's result, or why it has none (`error`: the exception, `detail`: its
    traceback)."""

    index: int
    case: Case
    result: LockstepResult | None
    error: str = ""
    detail: str = ""


Progress = Callable[[int, int, Outcome], None]
"""Called after each case: (cases done, cases in all, the case's outcome)."""

# A worker's renderer and configurations, built once per process.
_scenes: SceneCamera | None = None
_configs: dict[tuple[Path, Path | None, bool], LoopConfig] = {}


def _worker_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_case(index: int, case: Case) -> Outcome:
    """One case in this process (a worker's job; also the one-worker path)."""
    global _scenes
    try:
        if _scenes is None:
            _scenes = SceneCamera(Calibration.load(EXAMPLE_CALIBRATION))
        key = (case.fusion_config, case.candidate_config, case.ideal)
        if key not in _configs:
            _configs[key] = LoopConfig.load(case.fusion_config, case.candidate_config,
                                            case.ideal)
        result = run_scenario(case.scenario, _configs[key], _scenes, case.loop_seed)
    except Exception as exc:     # reported with the case; the other cases go on
        return Outcome(index, case, None, f"{type(exc).__name__}: {exc}",
                       traceback.format_exc())
    if case.plot is not None:
        try:
            _plot(result, _configs[key], case.plot)
        except OSError as exc:   # the run stands; its plot is missing, and said so
            return Outcome(index, case, result, detail=f"plot not written: {exc}")
    return Outcome(index, case, result)


def _plot(result: LockstepResult, config: LoopConfig, path: Path) -> None:
    # matplotlib only for the runs that draw (the plot module imports it)
    from aeb_radar_camera.tools.sim.plot import plot_timeline

    d = config.fusion.fusion.decision
    plot_timeline(result.samples, result.verdict, path, d.ttc_offset_s, d.brake_ttc_eff_s)


def run_cases(cases: Sequence[Case], workers: int = 2, progress: Progress | None = None,
              stop: threading.Event | None = None) -> list[Outcome]:
    """Every case's outcome, in the order given (fewer when `stop` was set: those
    finished by then). `workers` 1: in this process."""
    done: list[Outcome] = []
    for outcome in iter_cases(cases, workers, stop):
        done.append(outcome)
        if progress is not None:
            progress(len(done), len(cases), outcome)
    return sorted(done, key=lambda o: o.index)


def iter_cases(cases: Sequence[Case], workers: int = 2,
               stop: threading.Event | None = None) -> Iterator[Outcome]:
    """The outcomes as the cases finish. Once `stop` is set no case is started; the
    running ones finish."""
    if workers <= 1 or len(cases) <= 1:
        for i, case in enumerate(cases):
            if stop is not None and stop.is_set():
                return
            yield run_case(i, case)
        return
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(min(workers, len(cases)), mp_context=context,
                             initializer=_worker_init) as pool:
        submitted = {pool.submit(run_case, i, c): i for i, c in enumerate(cases)}
        pending: set[Future[Outcome]] = set(submitted)
        try:
            while pending:
                finished, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                for future in finished:
                    if future.cancelled():
                        continue
                    try:
                        yield future.result()
                    except BrokenProcessPool as exc:   # a worker died (killed, out of memory)
                        i = submitted[future]
                        yield Outcome(i, cases[i], None, f"worker process died: {exc}")
                if stop is not None and stop.is_set():
                    for future in pending:
                        future.cancel()
                    pending = {f for f in pending if not f.cancelled()}
        finally:
            for future in pending:
                future.cancel()


def print_progress(out: IO[str] = sys.stderr) -> Progress:
    """A line per case: how far, the verdict, its wall time against simulated time."""
    t0 = time.monotonic()

    def show(done: int, total: int, o: Outcome) -> None:
        elapsed = time.monotonic() - t0
        left = elapsed / done * (total - done)
        r = o.result
        if r is None:
            what = f"ERROR {o.error}"
        else:
            v = r.verdict
            what = (f"{'PASS' if v.passed else 'FAIL'} {v.outcome} "
                    f"({r.wall_s:.1f} s for {r.simulated_s:.1f} s simulated)")
        print(f"[{done}/{total}] {o.case.label}: {what}; {elapsed:.0f} s so far, about "
              f"{left:.0f} s left", file=out, flush=True)

    return show
