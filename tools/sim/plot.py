"""The timeline plot of a closed-loop run (PNG): range, speed, TTC, decision and brake
state, brake command and actuator position over time, with the verdict in the title."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from aeb_radar_camera.tools.sim.verdict import Sample, Verdict

DECISIONS = ["", "NONE", "WARNING", "BRAKE"]
STATES = ["", "STANDBY", "ARMED", "BRAKING", "FAILSAFE", "FAULT"]


def plot_timeline(samples: list[Sample], verdict: Verdict, path: str | Path,
                  ttc_eff_offset_s: float = 1.0, ttc_eff_brake_s: float = 2.5) -> Path:
    """Write the plot; returns its path (parent folders are created). Raises OSError."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    t = [s.t_s for s in samples]
    fig, axes = plt.subplots(5, 1, figsize=(10, 11), sharex=True)
    ax = axes[0]
    ax.plot(t, [s.gap_m if s.gap_m is not None else float("nan") for s in samples], "k-",
            label="obstacle")
    if any(s.false_target_gap_m is not None for s in samples):
        ax.plot(t, [s.false_target_gap_m if s.false_target_gap_m is not None else float("nan")
                    for s in samples], color="grey", ls="--",
                label="false target (radar only: nothing to hit)")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel("gap to in-path\nobject (m)")
    ax.axhline(0, color="r", lw=0.8)
    ax = axes[1]
    ax.plot(t, [s.ego_speed_mps * 3.6 for s in samples], "b-")
    ax.set_ylabel("ego speed (km/h)")
    ax = axes[2]
    ax.plot(t, [s.ttc_s if s.ttc_s is not None and s.ttc_s < 20 else float("nan")
                for s in samples], "m-", label="TTC (ground truth)")
    ax.axhline(ttc_eff_offset_s + ttc_eff_brake_s, color="r", ls="--", lw=0.8,
               label=f"BRAKE bound: TTC < {ttc_eff_offset_s + ttc_eff_brake_s:g} s "
                     f"(TTC_eff < {ttc_eff_brake_s:g} s)")
    ax.set_ylim(0, 10)
    ax.set_ylabel("TTC (s)")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[3]
    ax.step(t, [DECISIONS.index(s.decision) if s.decision in DECISIONS else 0
                for s in samples], "g-", where="post", label="fusion decision")
    ax.step(t, [STATES.index(s.brake_state) + 0.1 if s.brake_state in STATES else 0
                for s in samples], "c-", where="post", label="brake state", alpha=0.7)
    ax.set_yticks(range(1, 6), ["NONE\nSTANDBY", "WARNING\nARMED", "BRAKE\nBRAKING",
                                "FAILSAFE", "FAULT"], fontsize=7)
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[4]
    ax.plot(t, [s.commanded_pct for s in samples], "r-", label="commanded level")
    ax.plot(t, [s.position_pct for s in samples], "k-", label="actuator position")
    ax.set_ylabel("brake (%)")
    ax.set_ylim(-5, 105)
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper left", fontsize=8)
    if verdict.first_brake_t_s is not None:
        for a in axes:
            a.axvline(verdict.first_brake_t_s, color="orange", lw=0.8, ls=":")
    for a in axes:
        a.grid(alpha=0.3)
    result = "PASS" if verdict.passed else "FAIL"
    fig.suptitle(f"{verdict.scenario} ({verdict.kind.value}): {result}, {verdict.outcome}")
    fig.tight_layout()
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p
