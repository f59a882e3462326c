"""The pictures of an evidence folder: the frame a decision was checked in with every ROI
of the cycle drawn and labelled, the deciding ROI alone, and its Canny edges when the
verifier counts them.

A label has to be read at a glance on any picture: the text is set on a box of its
ROI's state colour (the colours of the live and recorded Foxglove views), black or white
whichever contrasts more with it, at a size that follows the frame's height (about 15 px
on a 480-line frame), above its ROI (below when the ROI touches the top) and kept inside
the frame. The deciding track's ROI is drawn thicker.
"""

from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.messages import VerifiedTarget, VerifiedTargets
from aeb_radar_camera.tools.recording.foxglove_views import (
    frame_stamp_ns,
    state_colour,
    target_label,
)

FONT = cv2.FONT_HERSHEY_SIMPLEX
TEXT_PX_PER_LINE = 15 / 480       # text height per frame line
PAD_PX = 3
BGR = tuple[int, int, int]


def luminance(bgr: BGR) -> float:
    """Relative luminance (WCAG 2) of an sRGB colour given as BGR 0..255."""
    def channel(c: int) -> float:
        v = c / 255
        return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4
    b, g, r = bgr
    return 0.2126 * channel(r) + 0.7152 * channel(g) + 0.0722 * channel(b)


def contrast(a: BGR, b: BGR) -> float:
    """WCAG contrast ratio, 1 (none) to 21 (black on white)."""
    hi, lo = sorted((luminance(a), luminance(b)), reverse=True)
    return (hi + 0.05) / (lo + 0.05)


def text_colour(background: BGR) -> BGR:
    """Black or white, whichever reads better on `background`."""
    black, white = (0, 0, 0), (255, 255, 255)
    return black if contrast(background, black) >= contrast(background, white) else white


def label_box(img: np.ndarray, text: str, roi: tuple[int, int, int, int],
              colour: BGR) -> tuple[int, int, int, int]:
    """Draw `text` on a box of `colour` by the ROI; returns the box (x, y, w, h)."""
    height, width = img.shape[:2]
    text_px = max(10, round(height * TEXT_PX_PER_LINE))
    thickness = max(1, round(text_px / 8))         # strokes that survive JPEG and a glance
    scale = cv2.getFontScaleFromHeight(FONT, text_px, thickness)
    (tw, th), base = cv2.getTextSize(text, FONT, scale, thickness)
    bw, bh = tw + 2 * PAD_PX, th + base + 2 * PAD_PX
    x, y, _, h = roi
    top = y - bh if y - bh >= 0 else min(height - bh, y + h)
    left = max(0, min(x, width - bw))
    cv2.rectangle(img, (left, top), (left + bw - 1, top + bh - 1), colour, cv2.FILLED)
    cv2.putText(img, text, (left + PAD_PX, top + PAD_PX + th), FONT, scale,
                text_colour(colour), thickness, cv2.LINE_AA)
    return left, top, bw, bh


def annotated(bgr: np.ndarray, targets: VerifiedTargets, deciding: VerifiedTarget,
              camera: str) -> np.ndarray:
    """The frame with every ROI of the cycle checked in it, boxed and labelled."""
    out = bgr.copy()
    boxes = [t for t in targets.targets if len(t.roi_xywh) == 4
             and frame_stamp_ns(targets, t) is not None and not (t.camera and t.camera != camera)]
    # the deciding one last: its label on top
    for t in sorted(boxes, key=lambda t: t.track_id == deciding.track_id):
        x, y, w, h = t.roi_xywh
        r, g, b, _ = state_colour(t)
        colour = (round(b * 255), round(g * 255), round(r * 255))
        cv2.rectangle(out, (x, y), (x + w - 1, y + h - 1), colour,
                      3 if t.track_id == deciding.track_id else 2)
        label_box(out, target_label(t, targets.verifier), (x, y, w, h), colour)
    return out


def write_images(folder: Path, bgr: np.ndarray, targets: VerifiedTargets,
                 deciding: VerifiedTarget, camera: str) -> list[str]:
    """frame_annotated.jpg, roi.png and (edge-density verifiers) roi_edges.png in
    `folder`; returns the names written."""
    cv2.imwrite(str(folder / "frame_annotated.jpg"), annotated(bgr, targets, deciding, camera))
    files = ["frame_annotated.jpg"]
    if len(deciding.roi_xywh) == 4:
        x, y, w, h = deciding.roi_xywh
        crop = bgr[y:y + h, x:x + w]
        if crop.size:
            cv2.imwrite(str(folder / "roi.png"), crop)
            files.append("roi.png")
            params = {**targets.verifier_params, **deciding.gate_detail}
            low, high = params.get("low"), params.get("high")
            if isinstance(low, int | float) and isinstance(high, int | float) and \
                    "edge_density" in targets.verifier:
                gray = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY)
                cv2.imwrite(str(folder / "roi_edges.png"),
                            cv2.Canny(gray, float(low), float(high)))
                files.append("roi_edges.png")
    return files
