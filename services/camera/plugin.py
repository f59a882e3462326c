"""Source plugins: a config names a factory, "package.module:callable", and the camera
builds its FrameSource from it. The scenario simulator's camera and the moving-box demo
scene (tools/sim/) are such plugins; a user plugs in their own source the same way.

Config::

    [camera.source]
    kind = "synthetic"
    factory = "aeb_radar_camera.tools.sim.camera_source:make_source"   # "package.module:callable"
    fps = 30                                           # 0: the camera's fps
    options = { stale_after_s = 1.0 }                  # passed through unchanged

The camera imports the module and calls ``factory(context)`` once, at start, with a
`PluginContext` (size and calibration of the camera, the pacing rate, the options, and
the camera's Bus when it runs inside the camera service). The factory returns a
`FrameSource` (services/camera/source.py), which the camera then drives like any other:
``open()``, ``read()`` repeatedly, ``close()``, all from one capture thread. ``read()``
returns a `Frame` (BGR uint8 (height, width, 3), wall-clock capture stamp in ns) and
paces itself (e.g. with `Pacer`); it raises `EndOfStream` when the source is exhausted
and `SourceError` when it fails. Frames must have the calibration's size. The factory
may raise `SourceConfigError` (or ValueError/TypeError/KeyError) for bad options: the
camera exits with code 2 and the message.
"""

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.services.camera.source import FrameSource, SourceConfigError

if TYPE_CHECKING:
    from aeb_radar_camera.common.bus import Bus


@dataclass(frozen=True)
class PluginContext:
    """What a source factory receives."""

    width: int
    height: int
    fps: float                       # the rate the source should deliver at
    calibration: Calibration | None  # the camera's calibration (None only in unit tests)
    camera: str = "front"
    options: dict[str, Any] = field(default_factory=dict)
    bus: "Bus | None" = None         # the camera's bus, e.g. to follow a simulated world


PluginFactory = Callable[[PluginContext], FrameSource]
# the repository's folders, installed under the package's name: a factory written with the
# folder's bare name (as configs did before) is told the name it has
_OWN_FOLDERS = ("common", "services", "tools")


def load_factory(path: str) -> PluginFactory:
    """The callable named by "package.module:attr". Raises SourceConfigError saying
    what is wrong (format, module not found, attribute missing, not callable)."""
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise SourceConfigError(f"synthetic factory {path!r}: expected 'package.module:callable'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        package = __name__.split(".")[0]
        hint = (f" (the stack's own modules are under {package}: "
                f"'{package}.{path}')" if module_name.split(".")[0] in _OWN_FOLDERS else "")
        raise SourceConfigError(f"synthetic factory {path!r}: cannot import module "
                                f"{module_name!r}: {exc}{hint}") from exc
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise SourceConfigError(
                f"synthetic factory {path!r}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise SourceConfigError(f"synthetic factory {path!r}: {attr!r} is not callable")
    factory: PluginFactory = obj
    return factory


def make_plugin_source(path: str, context: PluginContext) -> FrameSource:
    """Load the factory and build the source. Raises SourceConfigError."""
    factory = load_factory(path)
    try:
        source = factory(context)
    except SourceConfigError:
        raise
    except (ValueError, TypeError, KeyError) as exc:
        raise SourceConfigError(f"synthetic factory {path!r} rejected its options: {exc}") from exc
    if not isinstance(source, FrameSource):
        raise SourceConfigError(
            f"synthetic factory {path!r} returned {type(source).__name__}, not a FrameSource")
    return source
