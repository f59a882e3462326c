"""The shape every benchmark result takes, so that the suite can print one table, one
JSON file and one chart.

A figure is always measured beside its baseline in the same run (absolute times on a
shared machine drift by 20% or more between runs); `ratio` is value / baseline.
"""

import argparse
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class Figure:
    group: str                    # "gate", "latency", "scale", "cost", ...
    name: str                     # what was measured, e.g. "ROI 4.3% mean"
    value: float
    unit: str                     # "us", "ms", "%", "MB", "x", "Hz"
    baseline: str = ""            # what it is compared with, measured in the same run
    baseline_value: float | None = None
    target: str = ""              # the bar, in words ("< 3.75 ms"), empty when none
    target_met: bool | None = None
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ratio(self) -> float | None:
        if self.baseline_value in (None, 0):
            return None
        assert self.baseline_value is not None
        return self.value / self.baseline_value

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["ratio"] = self.ratio
        return d


def section_main(prog: str, doc: str | None, run: Callable[[bool, Path], object],
                 argv: list[str] | None, quick_help: str = "few frames and repetitions"
                 ) -> int:
    """`python -m benchmarks.<prog> [--quick] [--out DIR]` for a section that needs no
    other option: 0 once measured, 1 when the benchmark could not run (RuntimeError)."""
    parser = argparse.ArgumentParser(prog=prog, description=doc,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--out", default="out/bench", help="directory for JSON and PNG")
    args = parser.parse_args(argv)
    try:
        run(args.quick, Path(args.out))
    except RuntimeError as exc:
        print(f"error: {exc}")
        return 1
    return 0
