"""The radar's confirmed tracks on the bundled real recording, cycle by cycle, against a
stored expectation (tests/data/ars408/expected_tracks.json.gz): any change of the decoder,
prefilter, merge or tracker that moves a confirmed track fails here.

A deliberate change of behaviour rewrites the expectation, in the same commit, with
``python -m tests.radar.test_recording_expectation --write``.
"""

import argparse
import gzip
import json
import sys
from typing import Any

import pytest

from tests.can_support import run_recording
from tests.support import REPO

EXPECTED = REPO / "tests" / "data" / "ars408" / "expected_tracks.json.gz"

_EXACT = ("track_id", "hits", "misses", "radar_object_id", "dyn_prop", "obj_class")
_CLOSE = ("x_m", "y_m", "vx_mps", "vy_mps", "range_m", "range_rate_mps", "rcs_dbsm",
          "x_var_m2", "y_var_m2")


def observed() -> list[dict[str, Any]]:
    """Per cycle: its counter, detection counts and confirmed tracks."""
    _, results = run_recording()
    return [{
        "meas_counter": r.meas_counter,
        "n_detections": r.n_detections,
        "n_prefiltered": r.n_prefiltered,
        "confirmed": [{f: getattr(t, f) for f in (*_EXACT, *_CLOSE)}
                      for t in r.tracks if t.confirmed],
    } for r in results]


def test_confirmed_tracks_match_the_stored_expectation():
    expected = json.loads(gzip.decompress(EXPECTED.read_bytes()))
    got = observed()
    assert len(got) == len(expected) == 515
    assert sum(len(c["confirmed"]) for c in expected) > 500     # the scene is really tracked
    for k, (a, b) in enumerate(zip(got, expected, strict=True)):
        assert {f: a[f] for f in ("meas_counter", "n_detections", "n_prefiltered")} == \
            {f: b[f] for f in ("meas_counter", "n_detections", "n_prefiltered")}, f"cycle {k}"
        assert [[t[f] for f in _EXACT] for t in a["confirmed"]] == \
            [[t[f] for f in _EXACT] for t in b["confirmed"]], f"cycle {k}"
        for ta, tb in zip(a["confirmed"], b["confirmed"], strict=True):
            for f in _CLOSE:
                # to rounding: a matrix product may round differently in the last bit
                assert ta[f] == pytest.approx(tb[f], rel=1e-9, abs=1e-12), \
                    f"cycle {k} track {ta['track_id']} {f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--write", action="store_true", help="rewrite the stored expectation")
    args = p.parse_args(argv)
    if not args.write:
        p.print_help()
        return 2
    text = json.dumps(observed(), separators=(",", ":")) + "\n"
    EXPECTED.write_bytes(gzip.compress(text.encode(), mtime=0))
    print(f"wrote {EXPECTED}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
