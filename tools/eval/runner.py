"""Evaluation at scale: one task per recording (a data set: one per chunk of frames), run
in parallel over the machine's cores or on a Dask cluster with the same task function,
with a progress line.

`run_task` is the unit of work: it reads its input, builds every ROI and scores it with
every verifier, and returns the records. Locally the tasks run in a pool of spawned
processes (`jobs`); with `scheduler` ("tcp://host:port") they are submitted to that Dask
scheduler (the `eval` extra: dask[distributed]); the workers must be able to import this
project.
"""

import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import IO, Any

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError
from aeb_radar_camera.tools.eval.adapters import detect, frame_ids
from aeb_radar_camera.tools.eval.dataset_rois import DatasetSettings, dataset_records
from aeb_radar_camera.tools.eval.options import FRAMES_PER_TASK
from aeb_radar_camera.tools.eval.recording import RecordingSettings, recording_records
from aeb_radar_camera.tools.eval.records import RoiRecord
from aeb_radar_camera.tools.eval.scoring import Scorer, VerifierSpec
from aeb_radar_camera.tools.recording.reader import RecordingError


class SourceError(ValueError):
    """A source that is neither a recording nor a data set the adapters know."""


@dataclass(frozen=True)
class Task:
    """One unit of work: a recording (`kind` "recording", `path` the MCAP file) or some
    frames of a data set (`kind` "kitti" / "vod", `path` its split folder)."""

    kind: str
    path: str
    specs: tuple[VerifierSpec, ...]
    frames: tuple[str, ...] = ()
    recording: RecordingSettings = field(default_factory=RecordingSettings)
    dataset: DatasetSettings = field(default_factory=DatasetSettings)

    @property
    def name(self) -> str:
        if self.frames:
            return f"{self.path} [{self.frames[0]}..{self.frames[-1]}]"
        return self.path


@dataclass
class TaskResult:
    name: str
    records: list[RoiRecord]
    counters: dict[str, int]
    errors: list[str]
    seconds: float
    params: dict[str, dict[str, Any]]
    pid: int = 0


_SCORERS: dict[tuple[str, ...], Scorer] = {}


def _scorer(specs: tuple[VerifierSpec, ...]) -> Scorer:
    """One scorer per process and verifier set (building verifiers is not free)."""
    key = tuple(s.label for s in specs)
    if key not in _SCORERS:
        _SCORERS[key] = Scorer(list(specs))
    return _SCORERS[key]


def run_task(task: Task) -> TaskResult:
    """Build and score every ROI of one task. Never raises for bad input: the error is
    in `errors` and counted."""
    t0 = time.perf_counter()
    counters: dict[str, int] = {}
    errors: list[str] = []
    records: list[RoiRecord] = []
    try:
        scorer = _scorer(task.specs)
        if task.kind == "recording":
            records = recording_records(Path(task.path), task.recording, scorer, counters)
        else:
            records = dataset_records(task.kind, Path(task.path), list(task.frames),
                                      task.dataset, scorer, counters, errors)
        params = scorer.params()
    except (RecordingError, ConfigError, VerifierConfigError, OSError, ValueError) as exc:
        errors.append(f"{task.name}: {exc}")
        counters["task_failed"] = 1
        params = {}
    return TaskResult(task.name, records, counters, errors, time.perf_counter() - t0,
                      params, os.getpid())


def plan(sources: Sequence[str], specs: Sequence[VerifierSpec], recording: RecordingSettings,
         dataset: DatasetSettings, frames_per_task: int = FRAMES_PER_TASK,
         limit_frames: int = 0) -> list[Task]:
    """Tasks for recordings (files, or folders of them) and data-set folders (a split
    folder, or a root holding `training/`). Raises SourceError naming the source."""
    tasks: list[Task] = []
    spec_t = tuple(specs)
    for src in sources:
        p = Path(src)
        if p.is_file() and p.suffix == ".mcap":
            tasks.append(Task("recording", str(p), spec_t, recording=recording))
            continue
        if not p.is_dir():
            raise SourceError(f"{src}: no such recording (.mcap) or data-set folder")
        kind = detect(p)
        if kind is None and (p / "training").is_dir():
            p, kind = p / "training", detect(p / "training")
        if kind is not None:
            ids = frame_ids(kind, p)
            if limit_frames:
                ids = ids[:limit_frames]
            if not ids:
                raise SourceError(f"{src}: a {kind} folder without a complete frame")
            step = max(1, frames_per_task)
            tasks += [Task(kind, str(p), spec_t, tuple(ids[i:i + step]), dataset=dataset)
                      for i in range(0, len(ids), step)]
            continue
        recordings = sorted(p.rglob("*.mcap"))
        if not recordings:
            raise SourceError(f"{src}: neither a KITTI / View-of-Delft folder nor a folder "
                              "of .mcap recordings")
        tasks += [Task("recording", str(r), spec_t, recording=recording) for r in recordings]
    return tasks


class Progress:
    """A progress line on stderr: redrawn on a terminal, one line per task otherwise."""

    def __init__(self, total: int, out: IO[str] | None = None, width: int = 28) -> None:
        self.total = total
        self.out = out if out is not None else sys.stderr
        self.tty = self.out.isatty()
        self.width = width
        self.done = 0
        self.rois = 0
        self.t0 = time.monotonic()

    def update(self, result: TaskResult) -> None:
        self.done += 1
        self.rois += len(result.records)
        elapsed = time.monotonic() - self.t0
        rate = self.rois / elapsed if elapsed > 0 else 0.0
        eta = elapsed / self.done * (self.total - self.done)
        filled = round(self.width * self.done / max(self.total, 1))
        bar = "#" * filled + "." * (self.width - filled)
        text = (f"[{bar}] {self.done}/{self.total} tasks, {self.rois} ROIs, "
                f"{rate:.0f} ROIs/s, {elapsed:.0f} s, ETA {eta:.0f} s")
        if self.tty:
            self.out.write("\r" + text + "\x1b[K" + ("\n" if self.done == self.total else ""))
        else:
            self.out.write(text + f"  ({result.name}: {len(result.records)} ROIs)\n")
        self.out.flush()


def _worker_start() -> None:
    """Worker start-up: Ctrl-C is for the parent, which stops the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def _stop_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block is done, then raise KeyboardInterrupt: a
    worker being handed its start-up data must not be left reading half of it. (Python
    runs signal handlers in the main thread, whichever thread the kernel picked.)"""
    got: list[int] = []

    def note(signum: int, frame: object) -> None:
        got.append(signum)

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, note) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    if got:
        raise KeyboardInterrupt


def _indexed(item: tuple[int, Task]) -> tuple[int, TaskResult]:
    return item[0], run_task(item[1])


def _local(tasks: list[Task], jobs: int) -> Iterator[tuple[int, TaskResult]]:
    if jobs <= 1 or len(tasks) == 1:
        for i, t in enumerate(tasks):
            yield i, run_task(t)
        return
    pool = None
    try:
        with _stop_deferred():
            pool = get_context("spawn").Pool(min(jobs, len(tasks)),
                                             initializer=_worker_start)
        yield from pool.imap_unordered(_indexed, list(enumerate(tasks)))
        pool.close()
    finally:
        # Done, interrupted or failed: no worker outlives the call.
        if pool is not None:
            pool.terminate()
            pool.join()


def _dask(tasks: list[Task], scheduler: str) -> Iterator[tuple[int, TaskResult]]:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:
        raise SourceError("--scheduler needs Dask: pip install 'aeb-radar-camera[eval]'"
                          ) from exc
    with Client(scheduler, timeout="30s") as client:
        futures = client.map(run_task, tasks, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in dask_completed(futures):
            yield index[fut.key], fut.result()


def execute(tasks: list[Task], jobs: int = 1, scheduler: str = "",
            progress: Callable[[TaskResult], None] | None = None) -> list[TaskResult]:
    """Every task's result, in task order. Raises SourceError when Dask is asked for but
    missing; a scheduler that cannot be reached raises OSError."""
    results: list[TaskResult | None] = [None] * len(tasks)
    stream = _dask(tasks, scheduler) if scheduler else _local(tasks, jobs)
    for i, result in stream:
        results[i] = result
        if progress is not None:
            progress(result)
    return [r for r in results if r is not None]
