"""Appearance verifiers: what stands in the track's column, not how many edges it has.

Both look at a window centred on the projected column and scaled by its pixel height
(the column is 0 to `column_m` high at the track's range, so its height in pixels says
how large an obstacle at that range looks); a column cut by the frame's border is taken
as it is, and the window is filled beyond the frame by replicating its border pixels.

- `hog_people`: the pedestrian detector that OpenCV ships (Dalal and Triggs' HOG + linear
  SVM, `HOGDescriptor_getDefaultPeopleDetector` of OpenCV 4, Apache-2.0; its 3781
  coefficients are in `data/hog_people_detector.npy`). The window is resized so that a
  person of `person_m` standing at the column fills the detector's 64x128 window as in
  its training (96 px tall); the detector runs at every position of a small neighbourhood
  (3 strides each side, 2 up and down) and the score is the best SVM margin. It knows
  people only: cars and cyclists seen from behind score low.
- `hog_linear`: the HOG descriptor of the window (`window_w` x `window_h` px) and a
  linear classifier (logistic regression) trained on the user's labelled ROIs by `aeb
  train-verifier`, loaded from the weights file `weights` (JSON, see `HogLinearModel`).
  The score is the classifier's probability that the window holds an obstacle; `tau`
  defaults to the threshold the training chose (its target recall on held-out folds).
"""

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import hog
from aeb_radar_camera.services.fusion.verifiers.base import (
    GateResult,
    Observation,
    ParamValue,
    Verifier,
    VerifierConfigError,
    parse_params,
)

_PEOPLE_FILE = Path(__file__).parent.parent / "data" / "hog_people_detector.npy"
PEOPLE_WINDOW = (64, 128)       # the detector's window, w x h
PEOPLE_HEIGHT_PX = 96           # a person's height inside it, as trained
_SLACK_X, _SLACK_Y = 3, 2       # detector positions either side of the centred window

HOG_LINEAR_FORMAT = "aeb-hog-linear-1"


def window_around(gray: np.ndarray, cx: float, cy: float, scale: float,
                  size: tuple[int, int]) -> np.ndarray:
    """The `size` (w, h) window of the frame centred on (cx, cy) after scaling it by
    `scale`, beyond the frame filled by replicating its border. INTER_AREA when
    shrinking (no aliasing), bilinear when enlarging."""
    out_w, out_h = size
    half_w, half_h = out_w / (2.0 * scale), out_h / (2.0 * scale)
    x0, x1 = math.floor(cx - half_w), math.ceil(cx + half_w)
    y0, y1 = math.floor(cy - half_h), math.ceil(cy + half_h)
    h, w = gray.shape
    cx0, cy0 = min(max(x0, 0), w - 1), min(max(y0, 0), h - 1)
    cx1, cy1 = max(min(x1, w), cx0 + 1), max(min(y1, h), cy0 + 1)
    patch = gray[cy0:cy1, cx0:cx1]
    if (cx0, cy0, cx1, cy1) != (x0, y0, x1, y1):
        patch = cv2.copyMakeBorder(patch, cy0 - y0 if y0 < cy0 else 0,
                                   y1 - cy1 if y1 > cy1 else 0,
                                   cx0 - x0 if x0 < cx0 else 0,
                                   x1 - cx1 if x1 > cx1 else 0, cv2.BORDER_REPLICATE)
    shrink = patch.shape[0] > out_h
    return cv2.resize(patch, (out_w, out_h),
                      interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def _column_height(column: Roi) -> int:
    return max(column.h, 1)


class HogPeopleParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    # Best SVM margin at or above which a person is seen (OpenCV's own hit threshold: 0).
    tau: Annotated[float, msgspec.Meta(ge=-20, le=20)] = 0.0
    person_m: Annotated[float, msgspec.Meta(gt=0.3, le=2.5)] = 1.75
    column_m: Annotated[float, msgspec.Meta(gt=0.3, le=10)] = 2.2  # fusion's column height


def people_detector() -> tuple[np.ndarray, float]:
    """(coefficients, bias) of OpenCV's pedestrian detector. Raises OSError."""
    sv = np.load(_PEOPLE_FILE).astype(np.float32).ravel()
    return sv[:-1], float(sv[-1])


class HogPeople:
    """OpenCV's pedestrian HOG detector around the column."""

    name = "hog_people"
    needs_depth = False

    def __init__(self, p: HogPeopleParams) -> None:
        self.p = p
        self._w, self._b = people_detector()
        win_w, win_h = PEOPLE_WINDOW
        self._size = (win_w + 2 * _SLACK_X * hog.STRIDE, win_h + 2 * _SLACK_Y * hog.STRIDE)
        self._blocks = ((win_w - hog.BLOCK) // hog.STRIDE + 1,
                        (win_h - hog.BLOCK) // hog.STRIDE + 1)

    def params(self) -> dict[str, ParamValue]:
        return msgspec.structs.asdict(self.p)

    def verify(self, obs: Observation) -> GateResult:
        col = obs.column
        col_h = _column_height(col)
        person_px = col_h * self.p.person_m / self.p.column_m
        scale = PEOPLE_HEIGHT_PX / person_px
        cx = col.x + col.w / 2.0
        # The person stands on the column's foot; the window is centred on their middle.
        cy = col.y + col_h - person_px / 2.0
        window = window_around(obs.gray, cx, cy, scale, self._size)
        scores = hog.window_scores(hog.block_grid(window), self._w, self._b, self._blocks)
        best = float(scores.max())
        return GateResult(best, best >= self.p.tau, {"scale": scale}, "svm_margin")


def make_hog_people(params: Mapping[str, ParamValue]) -> Verifier:
    return HogPeople(parse_params(params, HogPeopleParams, "hog_people"))


@dataclass(frozen=True)
class HogLinearModel:
    """A linear classifier on the HOG descriptor of a column window: p = sigmoid(coef .
    descriptor + bias). `window`: (w, h) px, multiples of 8; `context`: the window's
    height over the column's; `tau`: the threshold the training chose; `trained_on`:
    what it was trained on (sources, frames, counts), kept with the weights."""

    window: tuple[int, int]
    context: float
    coef: np.ndarray
    bias: float
    tau: float
    trained_on: dict[str, Any]

    @property
    def n_features(self) -> int:
        w, h = self.window
        return ((w - hog.BLOCK) // hog.STRIDE + 1) * ((h - hog.BLOCK) // hog.STRIDE + 1) \
            * 4 * hog.BINS

    def to_json(self) -> dict[str, Any]:
        return {"format": HOG_LINEAR_FORMAT, "window": list(self.window),
                "context": self.context, "tau": self.tau, "bias": self.bias,
                "coef": [float(c) for c in self.coef], "trained_on": self.trained_on}

    def save(self, path: str | Path) -> None:
        """Raises OSError."""
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "HogLinearModel":
        """Raises VerifierConfigError naming the file and what is wrong with it."""
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise VerifierConfigError(f"hog_linear weights {path}: {exc}") from exc
        try:
            if data.get("format") != HOG_LINEAR_FORMAT:
                raise ValueError(f"format {data.get('format')!r}, expected "
                                 f"{HOG_LINEAR_FORMAT!r}")
            w, h = (int(v) for v in data["window"])
            if w < hog.BLOCK or h < hog.BLOCK or w % hog.CELL or h % hog.CELL:
                raise ValueError(f"window {w}x{h}: multiples of {hog.CELL}, at least "
                                 f"{hog.BLOCK}")
            model = cls((w, h), float(data["context"]),
                        np.asarray(data["coef"], np.float32), float(data["bias"]),
                        float(data["tau"]), dict(data.get("trained_on", {})))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise VerifierConfigError(f"hog_linear weights {path}: {exc}") from exc
        if model.coef.shape != (model.n_features,) or not np.all(np.isfinite(model.coef)):
            raise VerifierConfigError(
                f"hog_linear weights {path}: {model.coef.shape[0]} finite coefficients "
                f"expected {model.n_features} for a {w}x{h} window")
        return model


def hog_linear_window(obs: Observation, window: tuple[int, int], context: float
                      ) -> np.ndarray:
    """The grey window `hog_linear` describes: centred on the column, `context` times the
    column's height, the column's aspect given by the window."""
    col = obs.column
    scale = window[1] / (_column_height(col) * context)
    return window_around(obs.gray, col.x + col.w / 2.0, col.y + col.h / 2.0, scale, window)


def hog_linear_features(obs: Observation, window: tuple[int, int], context: float
                        ) -> np.ndarray:
    """What `hog_linear` classifies (and `aeb train-verifier` trains on)."""
    return hog.descriptor(hog_linear_window(obs, window, context))


def sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z)) if z >= 0 else math.exp(z) / (1.0 + math.exp(z))


class HogLinearParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    weights: str = ""               # the weights file (aeb train-verifier); required
    tau: Annotated[float, msgspec.Meta(ge=-1, le=1)] = -1.0  # < 0: the file's own tau


class HogLinear:
    """HOG of the column window and a trained linear classifier."""

    name = "hog_linear"
    needs_depth = False

    def __init__(self, p: HogLinearParams, model: HogLinearModel) -> None:
        self.p = p
        self.model = model
        self.tau = p.tau if p.tau >= 0 else model.tau

    def params(self) -> dict[str, ParamValue]:
        return {"weights": self.p.weights, "tau": self.tau}

    def verify(self, obs: Observation) -> GateResult:
        m = self.model
        x = hog_linear_features(obs, m.window, m.context)
        prob = sigmoid(float(x @ m.coef) + m.bias)
        return GateResult(prob, prob >= self.tau, score_name="probability")


def load_hog_linear(params: Mapping[str, ParamValue]) -> HogLinear:
    """Raises VerifierConfigError (no weights file, a bad one, bad params)."""
    p = parse_params(params, HogLinearParams, "hog_linear")
    if not p.weights:
        raise VerifierConfigError("verifier 'hog_linear' needs params.weights: a weights "
                                  "file from `aeb train-verifier`")
    return HogLinear(p, HogLinearModel.load(p.weights))


def make_hog_linear(params: Mapping[str, ParamValue]) -> Verifier:
    return load_hog_linear(params)
