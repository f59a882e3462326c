"""Verifiers: does the image show an obstacle inside a track's ROI?

A verifier takes an `Observation` of one track (the decoded grayscale frame, the ROI, the
projected column, the radar range, and aligned depth when the camera has it) and returns
a `GateResult`: a score (`score_name` says what it is), a verdict and how it got there.
A config selects one by name (`[fusion.verifier]`), so that an A/B instance can run
another without touching fusion; every published decision records the verifier's name
and parameters.

The names are a table (`BUILTIN`: name -> module and factory), as python-can's
interfaces are: a verifier's module is imported the first time its name is asked for, so
fusion loads only the verifier it runs and no verifier module imports another through
this one. Each factory validates its parameters (raises VerifierConfigError).

- `edge_density` (edge.py): the paper's gate. Canny(40, 120) on the ROI, d = edges /
  pixels, verified iff d >= tau (0.025).
- `adaptive_edge_density` (edge.py): the same gate made robust to night scenes.
- `depth` (depth.py): the share of the column's band whose depth puts a surface at the
  track's range.
- `hog_people`, `hog_linear` (appearance.py): HOG around the column, OpenCV's pedestrian
  detector or a linear classifier trained by `aeb train-verifier`.
- `combined` (combined.py): depth x appearance, one threshold.
- `recall_first` (recall_first.py): the shipped check. Vetoes a threat only on positive
  evidence that nothing stands at the radar's range.

To add one: a module in this package with a class that has `name`, `needs_depth`,
`params()` and `verify()`, a msgspec Struct for its parameters and a factory
`make(params) -> Verifier` (use `parse_params`), and one row in `BUILTIN`. A verifier may
also define `prepare(calibration)`: fusion calls it for each camera when it starts (the
depth verifier computes its ray maps there). Verifiers outside the package (tests,
experiments) can be added at run time with `@register("name")`.
"""

import importlib
from collections.abc import Callable, Mapping

import cv2

from aeb_radar_camera.services.fusion.verifiers.base import (
    Fraction,
    GateResult,
    Observation,
    ParamValue,
    Threshold,
    Verifier,
    VerifierConfigError,
    parse_params,
    wants_depth,
)

__all__ = ["BUILTIN", "Fraction", "GateResult", "Observation", "ParamValue", "Threshold",
           "Verifier", "VerifierConfigError", "VerifierFactory", "available", "create",
           "parse_params", "register", "wants_depth"]

# On a ROI this small, OpenCV's thread pool costs more than it gains (FACTS.md).
cv2.setNumThreads(1)

VerifierFactory = Callable[[Mapping[str, ParamValue]], Verifier]

# name -> (module in this package, its factory)
BUILTIN: dict[str, tuple[str, str]] = {
    "edge_density": ("edge", "make_edge_density"),
    "adaptive_edge_density": ("edge", "make_adaptive"),
    "depth": ("depth", "make"),
    "hog_people": ("appearance", "make_hog_people"),
    "hog_linear": ("appearance", "make_hog_linear"),
    "combined": ("combined", "make"),
    "recall_first": ("recall_first", "make"),
}

# Factories by name: those added with `register`, and the built-ins once loaded.
_REGISTRY: dict[str, VerifierFactory] = {}

def register(name: str) -> Callable[[VerifierFactory], VerifierFactory]:
    """Decorator: make a factory available under `name` (raises ValueError if taken,
    built-in names included)."""

    def add(factory: VerifierFactory) -> VerifierFactory:
        if name in _REGISTRY or name in BUILTIN:
            raise ValueError(f"verifier {name!r} is already registered")
        _REGISTRY[name] = factory
        return factory

    return add


def available() -> list[str]:
    return sorted(set(_REGISTRY) | set(BUILTIN))


def _factory(name: str) -> VerifierFactory | None:
    factory = _REGISTRY.get(name)
    if factory is None and name in BUILTIN:
        module, attr = BUILTIN[name]
        factory = getattr(importlib.import_module(f"{__name__}.{module}"), attr)
        _REGISTRY[name] = factory
    return factory


def create(name: str, params: Mapping[str, ParamValue] | None = None) -> Verifier:
    """A verifier by name. Raises VerifierConfigError naming the problem."""
    factory = _factory(name)
    if factory is None:
        raise VerifierConfigError(
            f"unknown verifier {name!r}; available: {', '.join(available())}")
    return factory(params or {})

