"""`aeb nodes`: the services and instances up on a vehicle's bus, as `ros2 node list`
lists nodes: every liveliness token `health/<service>/<instance>` (each service declares
its own once it serves, and it vanishes when the process dies).

    aeb nodes                                 # radar/front, camera/front, fusion/primary, ...
    aeb nodes --keys                          # and the keys each publishes (heard in 2 s)
    aeb nodes --json --connect tcp/192.168.10.1:7447

With `--keys`, a key belongs to the node its messages name as `header.source`; keys
heard from a source that holds no token (the simulator's ground truth, a replay) are
listed as such. Exit codes: 0, 1 when no node is up, 2 when the bus cannot be opened.
"""

import argparse
import json
import sys

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.keys import HEALTH
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, non_negative, open_bus
from aeb_radar_camera.tools.topics.catalog import Catalog
from aeb_radar_camera.tools.topics.list_keys import Listing

QUERY_TIMEOUT_S = 2.0


def tokens(bus: Bus, timeout_s: float = QUERY_TIMEOUT_S) -> list[str]:
    """`service/instance` of every liveliness token of the vehicle, sorted."""
    found = set()
    for reply in bus.session.liveliness().get(HEALTH.wildcard(bus.vehicle), timeout=timeout_s):
        if reply.ok is None:
            continue
        params = HEALTH.match(str(reply.ok.key_expr), bus.vehicle)
        if params is not None:
            found.add(f"{params['service']}/{params['instance']}")
    return sorted(found)


def keys_by_node(nodes: list[str], rows: list[dict[str, object]]) -> dict[str, list[str]]:
    """Each node's keys (a key's `header.source` is the node, or its service alone), and
    under "" the keys of sources that hold no token."""
    out: dict[str, list[str]] = {n: [] for n in nodes}
    out[""] = []
    for row in rows:
        publishers = row["publishers"]
        assert isinstance(publishers, list)
        for source in publishers:
            owner = next((n for n in nodes if source in (n, n.split("/")[0])), "")
            entry = str(row["key"]) if owner else f"{row['key']} ({source})"
            if entry not in out[owner]:
                out[owner].append(entry)
    return out


def render(nodes: list[str], keys: dict[str, list[str]] | None) -> str:
    if keys is None:
        return "\n".join(nodes) if nodes else "(no node up)"
    lines = []
    for node in nodes:
        lines.append(node)
        lines += [f"  {k}" for k in keys.get(node, [])] or ["  (nothing heard)"]
    if keys.get(""):
        lines.append("publishing without a health token:")
        lines += [f"  {k}" for k in keys[""]]
    return "\n".join(lines) if lines else "(no node up)"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb nodes", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keys", action="store_true",
                        help="also the keys each node publishes (listens --duration)")
    parser.add_argument("--duration", type=non_negative, default=2.0,
                        help="with --keys: listen this long (s), default 2")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    add_bus_args(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("nodes", args.log_level)
    stop = stop_event_on_signals()
    bus = open_bus(args, "nodes", stop)
    with bus:
        keys = None
        if args.keys:
            catalog = Catalog(args.vehicle)
            listing = Listing(catalog)
            bus.subscribe_expr(catalog.expression("**"), listing.on_sample)
            stop.wait(args.duration)
        nodes = tokens(bus)
        if args.keys:
            keys = keys_by_node(nodes, listing.rows(False))
    if args.json:
        print(json.dumps({"vehicle": args.vehicle, "nodes": nodes}
                         | ({"keys": keys} if keys is not None else {})))
    else:
        print(render(nodes, keys))
    return 0 if nodes else 1


if __name__ == "__main__":
    sys.exit(main())
