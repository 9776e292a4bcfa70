"""Optional dependencies of the visualization layer, imported lazily with an install hint."""

from __future__ import annotations

import importlib
import warnings
from types import ModuleType

from pinobs.errors import PinobsError

__all__ = ["MissingDependencyError", "require"]

_HINTS = {
    "meshcat": "pip install meshcat  (or: pip install 'pinobs[viz]')",
    "matplotlib": "pip install matplotlib  (or: pip install 'pinobs[plot]')",
}


class MissingDependencyError(PinobsError, ImportError):
    """An optional package needed by a visualization feature is not installed."""


def require(module: str, feature: str) -> ModuleType:
    """Import ``module`` or raise :class:`MissingDependencyError` naming ``feature`` and the fix."""
    try:
        with warnings.catch_warnings():
            # meshcat's server module imports zmq.eventloop.ioloop, deprecated since pyzmq 17
            warnings.filterwarnings(
                "ignore",
                message=r"zmq\.eventloop\.ioloop is deprecated",
                category=DeprecationWarning,
            )
            return importlib.import_module(module)
    except ImportError as exc:
        top = module.split(".")[0]
        hint = _HINTS.get(top, f"pip install {top}")
        raise MissingDependencyError(
            f"{feature} needs the {top!r} package, which is not importable ({exc}); "
            f"install it with: {hint}"
        ) from exc
