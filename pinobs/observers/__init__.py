"""Observer layer: the protocol, the registry and one module per family.

The protocol is ``base`` (with its helpers ``checks``, ``gating``, ``registry`` and
``results``, re-exported by ``base``); the other modules are the families and their
algebra.  Importing the package imports them all, and each family registers itself
with ``@register``.
"""

import importlib
import pkgutil

from pinobs.observers.base import (
    Consistency,
    Estimate,
    Observer,
    make_observer,
    observer_class,
    observer_names,
    positive,
    register,
)

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
    if _info.name != "base" and not _info.name.startswith("_"):
        importlib.import_module(f"{__name__}.{_info.name}")

__all__ = [
    "Consistency",
    "Estimate",
    "Observer",
    "make_observer",
    "observer_class",
    "observer_names",
    "positive",
    "register",
]
