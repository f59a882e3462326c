"""Every fault the harness injects, in the order a round injects them."""

from aeb_radar_camera.tools.faults.catalogue import CameraImpostorFrames, Fault, catalogue
from aeb_radar_camera.tools.faults.robust import BadConfigStrings, BadReplayStamps
from aeb_radar_camera.tools.faults.security import (
    BrakeRestartMidStop,
    PublishedKey,
    StuckSubscriber,
    TrackFlood,
)


def all_faults() -> list[Fault]:
    """The catalogue's faults, then those of bad input that must end in a named refusal
    (a picture frozen under fresh noise, NUL bytes in a config, bad replay stamps), then
    a key holder, a flood, a restart and a stuck subscriber (the published key, a radar
    track flood, a brake restarted mid-stop, a subscriber of every key frozen)."""
    return [*catalogue(),
            CameraImpostorFrames("noisy"), BadConfigStrings(), BadReplayStamps(),
            PublishedKey(), TrackFlood(), BrakeRestartMidStop(), StuckSubscriber()]
