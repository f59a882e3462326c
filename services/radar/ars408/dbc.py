"""The signal table exported as a DBC file, for CAN tools (cantools, SavvyCAN, Vector,
Wireshark) and as a cross-check. Generated, never edited by hand:

    python -m aeb_radar_camera.services.radar.ars408.dbc --write

A test checks that the shipped file equals what the table renders.
"""

import argparse
import sys

from aeb_radar_camera.common.resources import ARS408_DBC
from aeb_radar_camera.services.radar.ars408.table import MESSAGES, MessageSpec, Signal

DBC_PATH = ARS408_DBC

_NODES = {"ARS408": "HOST", "HOST": "ARS408"}


def _num(v: float) -> str:
    return f"{v:.10g}"


def _signal_line(sig: Signal, receiver: str) -> str:
    lo = sig.offset
    hi = sig.offset + sig.mask * sig.scale
    unit = "" if sig.unit == "code" else sig.unit
    return (f" SG_ {sig.dbc_name} : {sig.dbc_start_bit}|{sig.length}@0+ "
            f"({_num(sig.scale)},{_num(sig.offset)}) [{_num(lo)}|{_num(hi)}] "
            f'"{unit}" {receiver}')


def _message_block(m: MessageSpec) -> list[str]:
    lines = [f"BO_ {m.base_id} {m.dbc_name}: {m.dlc} {m.sender}"]
    lines += [_signal_line(s, _NODES[m.sender]) for s in m.signals]
    return [*lines, ""]


def render() -> str:
    """The DBC text (SensorID 0: add 0x10 * SensorID to every ID for other radars)."""
    out = [
        'VERSION ""',
        "",
        "NS_ :",
        "\tCM_",
        "\tVAL_",
        "",
        "BS_:",
        "",
        "BU_: ARS408 HOST",
        "",
    ]
    for m in MESSAGES:
        out += _message_block(m)
    out.append('CM_ "Continental ARS408-21, generated from services/radar/ars408/table.py. '
               'Motorola byte order; DistLat is left positive; IDs for SensorID 0 '
               '(add 0x10 * SensorID).";')
    for m in MESSAGES:
        if m.comment:
            out.append(f'CM_ BO_ {m.base_id} "{m.comment}";')
    out.append("")
    for m in MESSAGES:
        for s in m.signals:
            if s.choices:
                pairs = " ".join(f'{k} "{v}"' for k, v in sorted(s.choices.items()))
                out.append(f"VAL_ {m.base_id} {s.dbc_name} {pairs} ;")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--write", action="store_true", help=f"write {DBC_PATH.name}")
    args = parser.parse_args(argv)
    text = render()
    if args.write:
        DBC_PATH.write_text(text, encoding="utf-8")
        print(f"wrote {DBC_PATH}")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
