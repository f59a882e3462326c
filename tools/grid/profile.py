"""Where a lockstep run's wall time goes, by part (`with profile.part("render"):`)."""

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

PARTS = ("world", "radar", "fusion", "render", "jpeg_encode", "jpeg_decode", "depth_codec",
         "brake")


@dataclass
class Profile:
    """Seconds of wall time per part; `fusion` includes the frames it had rendered and
    decoded on demand (`render`, `jpeg_*`, `depth_codec`), so fusion's own work (the
    verifier, the decision) is `fusion_own_s`."""

    seconds: dict[str, float] = field(default_factory=lambda: dict.fromkeys(PARTS, 0.0))
    frames_captured: int = 0
    frames_rendered: int = 0

    @contextmanager
    def part(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] += time.perf_counter() - t0

    @property
    def fusion_own_s(self) -> float:
        s = self.seconds
        return s["fusion"] - s["render"] - s["jpeg_encode"] - s["jpeg_decode"] - s["depth_codec"]
