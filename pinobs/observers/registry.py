"""The registry of observer families: each registers itself by name (``@register``)."""

from __future__ import annotations

import importlib
import inspect
from typing import TYPE_CHECKING, Any, TypeVar

from pinobs.errors import OptionError, UnknownNameError
from pinobs.model import Robot
from pinobs.observers.blas import one_blas_thread

if TYPE_CHECKING:
    from pinobs.observers.base import Observer

__all__ = ["FAMILY_MODULES", "make_observer", "observer_class", "observer_names", "register"]

_REGISTRY: dict[str, type[Observer[Any]]] = {}

#: pinobs's observer families by name -> the module that defines (and registers) each,
#: imported when the family is first asked for: a program imports only the families it uses
#: (issue 39, start-up time).  ``tests/observers/test_registry.py`` checks it against what
#: the modules register.
FAMILY_MODULES = {
    "adaptive": "pinobs.observers.adaptive",
    "ekf": "pinobs.observers.ekf",
    "fd": "pinobs.observers.fd",
    "highgain": "pinobs.observers.differentiators",
    "ii": "pinobs.observers.ii",
    "kalman": "pinobs.observers.ibrir_kalman",
    "kf": "pinobs.observers.kf",
    "liegroup": "pinobs.observers.liegroup",
    "riemannian": "pinobs.observers.riemannian",
    "sliding": "pinobs.observers.differentiators",
}

ObserverType = TypeVar("ObserverType", bound="type[Observer[Any]]")


def register(cls: ObserverType) -> ObserverType:
    """Class decorator: add an observer family to the registry under ``cls.name``."""
    if not cls.name or cls.name in _REGISTRY:
        raise ValueError(f"observer name {cls.name!r} is empty or already registered")
    _REGISTRY[cls.name] = cls
    return cls


def observer_names() -> list[str]:
    """Observer names (pinobs's families and any registered since), sorted."""
    return sorted(set(FAMILY_MODULES) | set(_REGISTRY))


def observer_class(name: str) -> type[Observer[Any]]:
    """The class registered under ``name``.

    Raises:
        UnknownNameError: listing the registered names.
    """
    if name not in _REGISTRY and name in FAMILY_MODULES:
        importlib.import_module(FAMILY_MODULES[name])  # registers it
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownNameError(
            f"unknown observer {name!r}; available: {', '.join(observer_names())}"
        ) from None


@one_blas_thread  # a family's gains (scipy's DARE...): a woken BLAS thread spins ~50 ms after
def make_observer(name: str, robot: Robot, **options: Any) -> Observer[Any]:
    """Build the observer registered as ``name`` on ``robot``.

    Options are the keyword arguments of the family's constructor (every
    family accepts ``rate`` [Hz] and ``noise_std`` [rad or m]), and
    ``latency`` [s] for every family (:meth:`Observer.set_latency`), and
    ``never_behind=True`` for a model-based family: the family blended per joint with
    the model-free ``kf`` (:class:`pinobs.observers.neverbehind.NeverBehind`; its
    ``window``, ``sharpness``, ``lost_ratio``, ``prior_log_odds``, ``reference_options``
    then accepted too).

    Raises:
        UnknownNameError: unknown ``name``.
        OptionError: an option the family does not accept (the message lists them).
        GainError: an option out of range.
    """
    cls = observer_class(name)
    latency = options.pop("latency", None)
    never_behind = bool(options.pop("never_behind", False))
    blend = {k: options.pop(k) for k in _BLEND_OPTIONS if never_behind and k in options}
    accepted = [
        p.name
        for p in inspect.signature(cls.__init__).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise OptionError(
            f"observer {name!r} does not accept option(s) {unknown}; accepted: {accepted}"
            + ("" if never_behind else ", and never_behind (model-based families)")
        )
    if never_behind:  # the family blended with kf (pinobs.observers.neverbehind)
        from pinobs.observers.neverbehind import NeverBehind

        given = {k: options.pop(k) for k in ("rate", "noise_std") if k in options}
        observer: Observer[Any] = NeverBehind(
            robot, observer=name, options=options, **blend, **given
        )
    else:
        observer = cls(robot, **options)
    if latency is not None:
        observer.set_latency(latency)
    return observer


#: Options of :class:`pinobs.observers.neverbehind.NeverBehind` that ``make_observer`` passes
#: to it with ``never_behind=True``.
_BLEND_OPTIONS = ("window", "sharpness", "lost_ratio", "prior_log_odds", "reference_options")
