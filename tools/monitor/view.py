"""The monitor's picture of the bus: a JSON-able snapshot of `MonitorState`, and the
same snapshot as a text table for a terminal or a log."""

import time
from typing import Any

from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_INFO,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_STATUS,
    RADAR_TRACKS,
    KeySpec,
)
from aeb_radar_camera.tools.keys import SIM_WORLD
from aeb_radar_camera.tools.monitor.state import MonitorState

_NS = 1_000_000_000
MAX_ROWS = 12


def _round(v: float | None, digits: int = 2) -> float | None:
    return None if v is None else round(v, digits)


def _messages(state: MonitorState, spec: KeySpec[Any]) -> list[Any]:
    return [msg for _, msg, _ in state.newest(spec)]


def snapshot(state: MonitorState, now_mono_ns: int, vehicle: str, endpoint: str) -> dict[str, Any]:
    """Everything the monitor shows, as plain data (also the `--json` output)."""
    snap: dict[str, Any] = {
        "endpoint": endpoint, "vehicle": vehicle, "same_host": state.same_host,
        "health": [vars(h) | {"since_s": round(h.since_s, 1)}
                   for h in state.health_views(now_mono_ns)],
        "keys": [], "radar": {}, "tracks": {}, "targets": {}, "commands": {}, "brake": None,
        "camera": {}, "sim": None, "decode_errors": dict(state.decode_errors),
    }
    for kv in state.key_views(now_mono_ns):
        snap["keys"].append({
            "key": kv.key, "count": kv.count, "rate_hz": round(kv.rate_hz, 1),
            "nominal_hz": _round(kv.nominal_hz, 1), "last_s": round(kv.last_age_s, 2),
            "status": "ok" if kv.on_rate else ("off-rate" if kv.alive else "STALE"),
            "age_p50_ms": _round(kv.age_p50_ms), "age_p99_ms": _round(kv.age_p99_ms),
            "transport_p50_ms": _round(kv.transport_p50_ms, 3),
            "transport_p99_ms": _round(kv.transport_p99_ms, 3), "seq_gaps": kv.seq_gaps,
        })
    for msg in _messages(state, RADAR_STATUS):
        snap["radar"][msg.sensor] = {
            "ready": msg.ready, "reason": msg.not_ready_reason, "bus": msg.bus_state.value,
            "interface": msg.interface, "channel": msg.channel,
            "cycle_ms": round(msg.cycle_period_ms, 1), "frames_per_s": round(msg.frames_per_s),
            "cycles": msg.cycles_total, "incomplete": msg.cycles_incomplete,
            "rejected": dict(msg.rejected)}
    for msg in _messages(state, RADAR_TRACKS):
        snap["tracks"][msg.sensor] = {
            "meas_counter": msg.meas_counter, "complete": msg.complete,
            "detections": msg.n_detections, "processing_us": round(msg.processing_ns / 1e3),
            "tracks": [{"id": t.track_id, "x_m": round(t.x_m, 2), "y_m": round(t.y_m, 2),
                        "range_m": round(t.range_m, 2), "rate_mps": round(t.range_rate_mps, 2),
                        "rcs": round(t.rcs_dbsm, 1), "hits": t.hits,
                        "confirmed": t.confirmed} for t in msg.tracks]}
    for msg in _messages(state, FUSION_TARGETS):
        snap["targets"][msg.instance] = {
            "verifier": msg.verifier, "status": msg.verifier_status.value,
            "unavailable_reason": msg.unavailable_reason, "radar_seq": msg.radar_seq,
            "processing_us": round(msg.processing_ns / 1e3),
            "targets": [{"id": t.track_id, "range_m": round(t.range_m, 2),
                         "y_m": round(t.y_m, 2), "in_path": t.in_path,
                         "verification": t.verification.value,
                         "density": _round(t.density, 3), "ttc_s": _round(t.ttc_s),
                         "ttc_eff_s": _round(t.ttc_eff_s), "decision": t.decision.value,
                         "reason": t.reason} for t in msg.targets]}
    for msg in _messages(state, FUSION_BRAKE_CMD):
        snap["commands"][msg.instance] = {
            "seq": msg.header.seq, "decision": msg.decision.value,
            "level_pct": msg.brake_level_pct, "held": msg.held, "track": msg.track_id,
            "range_m": _round(msg.range_m), "ttc_s": _round(msg.ttc_s), "reason": msg.reason,
            "verifier_status": msg.verifier_status.value}
    for msg in _messages(state, BRAKE_STATUS):
        snap["brake"] = {
            "state": msg.state.value, "reason": msg.reason, "instance": msg.instance,
            "policy": msg.policy.value, "level_pct": msg.commanded_level_pct,
            "position_pct": _round(msg.actuator_position_pct, 1),
            "actuator": msg.actuator_state, "connected": msg.actuator_connected,
            "cmd_to_serial_us": _round(msg.cmd_to_serial_us, 0),
            "radar_to_serial_us": _round(msg.radar_to_serial_us, 0),
            "rejected": dict(msg.rejected), "counters": dict(msg.counters)}
    for msg in _messages(state, CAMERA_INFO):
        snap["camera"][msg.camera] = {
            "source": msg.source, "healthy": msg.healthy, "status": msg.status,
            "fps": msg.fps, "published": msg.frames_published, "dropped": msg.frames_dropped,
            "read_errors": msg.read_errors}
    for msg in _messages(state, SIM_WORLD):
        snap["sim"] = {"scenario": msg.scenario, "active": msg.active, "t_s": round(msg.t_s, 2),
                       "ego_speed_kph": round(msg.ego_speed_mps * 3.6, 1),
                       "gap_m": _round(msg.gap_m), "ttc_s": _round(msg.ttc_s),
                       "objects": len(msg.objects)}
    return snap


def _f(v: Any, fmt: str = "", none: str = "-") -> str:
    if v is None:
        return none
    return format(v, fmt) if fmt else str(v)


def render_text(snap: dict[str, Any], now_wall: float | None = None) -> str:
    """The snapshot as a text table (about 100 columns)."""
    clock = time.strftime("%H:%M:%S", time.localtime(now_wall or time.time()))
    lines = [f"AEB monitor  {snap['endpoint']}  vehicle {snap['vehicle']}  {clock}"
             + ("" if snap["same_host"] else "  (remote: no transport latency)")]
    health = "  ".join(f"{h['service']}/{h['instance']} {'UP' if h['alive'] else 'DOWN'}"
                       f" {h['since_s']:.0f}s" for h in snap["health"])
    lines += ["", "HEALTH   " + (health or "no liveliness token seen")]
    lines += ["", f"{'KEY':<38} {'count':>7} {'Hz':>6} {'nom':>5} {'last s':>6} "
                  f"{'age p50/p99 ms':>15} {'hop p50/p99 ms':>15} {'gaps':>5} status"]
    for k in snap["keys"]:
        key = k["key"].split("/", 2)[-1]
        age = f"{_f(k['age_p50_ms'], '.1f')}/{_f(k['age_p99_ms'], '.1f')}"
        hop = f"{_f(k['transport_p50_ms'], '.2f')}/{_f(k['transport_p99_ms'], '.2f')}"
        lines.append(f"{key:<38} {k['count']:>7} {k['rate_hz']:>6.1f} "
                     f"{_f(k['nominal_hz'], '.0f'):>5} {k['last_s']:>6.1f} {age:>15} "
                     f"{hop:>15} {k['seq_gaps']:>5} {k['status']}")
    b = snap["brake"]
    lines.append("")
    if b is None:
        lines.append("BRAKE    no status")
    else:
        lines.append(f"BRAKE    {b['state']} ({b['reason']})  follows {b['instance']}  "
                     f"policy {b['policy']}  level {b['level_pct']:.0f}%  actuator "
                     f"{_f(b['position_pct'], '.1f')}% {b['actuator']}"
                     f"{'' if b['connected'] else ' DISCONNECTED'}  cmd->serial "
                     f"{_f(b['cmd_to_serial_us'], '.0f')} us  radar->serial "
                     f"{_f(b['radar_to_serial_us'], '.0f')} us")
        if any(b["rejected"].values()):
            lines.append(f"         rejected {b['rejected']}")
    for inst, c in sorted(snap["commands"].items()):
        lines.append(f"COMMAND  {inst:<10} #{c['seq']} {c['decision']:<7} {c['level_pct']:.0f}%"
                     f"{' held' if c['held'] else ''}  track {c['track']}  range "
                     f"{_f(c['range_m'], '.1f')} m  ttc {_f(c['ttc_s'], '.2f')} s  "
                     f"[{c['verifier_status']}] {c['reason']}")
    for sensor, r in sorted(snap["radar"].items()):
        lines.append(f"RADAR    {sensor}: {'ready' if r['ready'] else 'NOT READY ' + r['reason']}"
                     f"  bus {r['bus']} ({r['interface']} {r['channel']})  cycle "
                     f"{r['cycle_ms']} ms  {r['frames_per_s']} frames/s  cycles {r['cycles']}"
                     f" ({r['incomplete']} incomplete)")
    for cam, c in sorted(snap["camera"].items()):
        lines.append(f"CAMERA   {cam}: {c['source']} {'healthy' if c['healthy'] else 'UNHEALTHY'}"
                     f" {c['status']}  published {c['published']}  dropped {c['dropped']}  "
                     f"read errors {c['read_errors']}")
    for sensor, t in sorted(snap["tracks"].items()):
        tracks = t["tracks"]
        confirmed = sum(1 for x in tracks if x["confirmed"])
        lines += ["", f"TRACKS   {sensor}: {len(tracks)} ({confirmed} confirmed), "
                      f"{t['detections']} detections, {t['processing_us']} us"]
        if tracks:
            lines.append(f"  {'id':>4} {'x m':>7} {'y m':>6} {'range':>7} {'rate':>6} "
                         f"{'rcs':>5} {'hits':>4}  confirmed")
        for x in sorted(tracks, key=lambda x: x["range_m"])[:MAX_ROWS]:
            lines.append(f"  {x['id']:>4} {x['x_m']:>7.2f} {x['y_m']:>6.2f} "
                         f"{x['range_m']:>7.2f} {x['rate_mps']:>6.2f} {x['rcs']:>5.1f} "
                         f"{x['hits']:>4}  {'yes' if x['confirmed'] else 'no'}")
    for inst, t in sorted(snap["targets"].items()):
        lines += ["", f"TARGETS  {inst}: verifier {t['verifier']} [{t['status']}"
                      f"{' ' + t['unavailable_reason'] if t['unavailable_reason'] else ''}]"
                      f"  radar #{t['radar_seq']}  {t['processing_us']} us"]
        if t["targets"]:
            lines.append(f"  {'id':>4} {'range':>6} {'y m':>6} {'path':>4} {'verification':<12}"
                         f" {'dens':>6} {'ttc':>6} {'eff':>6} {'decision':<8} reason")
        for x in sorted(t["targets"], key=lambda x: x["range_m"])[:MAX_ROWS]:
            lines.append(f"  {x['id']:>4} {x['range_m']:>6.1f} {x['y_m']:>6.2f} "
                         f"{'in' if x['in_path'] else 'out':>4} {x['verification']:<12} "
                         f"{_f(x['density'], '.3f'):>6} {_f(x['ttc_s'], '.2f'):>6} "
                         f"{_f(x['ttc_eff_s'], '.2f'):>6} {x['decision']:<8} {x['reason']}")
    sim = snap["sim"]
    if sim is not None:
        lines += ["", f"SIM      {sim['scenario'] or '-'} {'running' if sim['active'] else 'idle'}"
                      f"  t {sim['t_s']:.1f} s  ego {sim['ego_speed_kph']:.1f} km/h  gap "
                      f"{_f(sim['gap_m'], '.1f')} m  ttc {_f(sim['ttc_s'], '.2f')} s  "
                      f"objects {sim['objects']}  (simulation ground truth)"]
    if snap["decode_errors"]:
        lines.append(f"UNDECODABLE payloads by key: {snap['decode_errors']}")
    return "\n".join(lines)
