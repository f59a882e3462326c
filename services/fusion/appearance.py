"""The appearance verifiers moved to services/fusion/verifiers/appearance.py; this name
is kept for the evaluation tools (tools/eval), which import HogLinearModel and
hog_linear_features from here."""

from services.fusion.verifiers.appearance import HogLinearModel, hog_linear_features

__all__ = ["HogLinearModel", "hog_linear_features"]
