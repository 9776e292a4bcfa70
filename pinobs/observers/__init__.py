"""Observer layer: the protocol, the registry and one module per family.

The protocol is ``base`` (with its helpers ``checks``, ``gating``, ``registry`` and
``results``, re-exported by ``base``); the other modules are the families and their
algebra.  Each family registers itself with ``@register`` when its module is imported;
importing the package imports none of them: :func:`make_observer` (and
:func:`observer_class`) import a family's module when it is first asked for
(:data:`~pinobs.observers.registry.FAMILY_MODULES`), so a program pays the start-up of the
families it uses only (issue 39).
"""

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
