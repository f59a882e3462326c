"""The shipped sample drive is exactly what its script writes, and cantools decodes
every frame of it through the sample DBC but the ones the script spoils on purpose."""

from collections import Counter
from typing import Any

import cantools
from can.io.canutils import CanutilsLogReader

from tests.vehicle.drive import FOREIGN_ID, LOG, render
from tests.vehicle.helpers import DB, decoded


def test_the_shipped_log_is_what_the_script_writes():
    assert LOG.read_text() == render(), "run: python -m tests.vehicle.drive --write"


def test_cantools_decodes_every_frame_but_the_spoilt_ones():
    outcome: Counter[str] = Counter()
    gears: Counter[str] = Counter()
    names: dict[int, Any] = dict(DB.get_message_by_name("Gear").get_signal_by_name(
        "GearLever").choices or {})
    for msg in CanutilsLogReader(str(LOG)):
        try:
            values = decoded(msg)
        except KeyError:
            outcome[f"unknown {msg.arbitration_id:#x}"] += 1
            continue
        except cantools.database.DecodeError:
            outcome[f"short {DB.get_message_by_frame_id(msg.arbitration_id).name}"] += 1
            continue
        outcome["decoded"] += 1
        if "GearLever" in values:
            gears[str(names[values["GearLever"]])] += 1
    assert outcome == {"decoded": 4939, f"unknown {FOREIGN_ID:#x}": 130, "short Brake": 1}
    assert gears == {"P": 10, "D": 102, "N": 2, "R": 15, "Invalid": 1}
