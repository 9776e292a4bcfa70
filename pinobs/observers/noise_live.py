"""σ from the data, live: an observer built without ``noise_std`` keeps its first updates,
estimates σ from them, rebuilds itself with it and replays them (the
:class:`~pinobs.observers.base.Observer` class docstring, **σ from the data, live**).

:func:`learn_noise` is what :meth:`~pinobs.observers.base.Observer.update` calls while σ is
unknown; :func:`with_noise_std` the observer it rebuilds.
"""

from __future__ import annotations

import copy
import warnings
from typing import Any

import numpy as np

from pinobs.errors import NoiseWarning
from pinobs.model.robot import Vector
from pinobs.observers.noise import NOISE_WINDOW, estimate_noise_std, window_times

__all__ = ["learn_noise", "with_noise_std"]


def learn_noise(observer: Any, t: float, q: Vector | None, tau: Vector, floor: float) -> bool:
    """Keep the update of ``observer`` until :data:`~pinobs.observers.noise.NOISE_WINDOW` s (and
    :data:`~pinobs.observers.noise.NOISE_MIN_SAMPLES` samples) are in; then σ̂ from them and,
    if it is above ``floor`` (:data:`~pinobs.observers.base.NOISE_FLOOR`) and changes the gains,
    rebuild it with σ̂ and replay the kept updates (warned once).  Returns whether the observer
    was rebuilt (its latest estimate is then the replay's)."""
    assert observer._noise_samples is not None
    observer._noise_samples.append((t, q, tau))
    ts = window_times(observer._noise_samples)
    if ts is None:
        return False
    kept, observer._noise_samples = observer._noise_samples, None
    qs = np.array([x[1] for x in kept if x[1] is not None])
    sigma_joint = estimate_noise_std(np.array(ts), qs, observer.robot, window=NOISE_WINDOW)
    if sigma_joint is None or not float(np.median(sigma_joint)) > floor:
        return False
    sigma = float(np.median(sigma_joint))
    fresh = with_noise_std(observer, sigma)
    if fresh is None:
        return False  # its gains were given: σ changes nothing
    fresh.reset(*observer._reset_args)
    fresh.set_latency(observer.latency)  # after its reset: a copy (twin) has had updates
    for tk, qk, tauk in kept:  # the same updates, as if σ̂ had been given from the start
        fresh.update(tk, qk, tauk)
    observer.__dict__ = fresh.__dict__
    warnings.warn(
        NoiseWarning(
            f"{observer.name}: built without noise_std; estimated σ = {sigma:.3g} from its "
            f"first {ts[-1] - ts[0]:.3g} s of samples (median over joints; per joint "
            f"{np.array2string(sigma_joint, precision=3)}), rebuilt with it and replayed "
            "them; pass noise_std to set it yourself"
        ),
        stacklevel=3,
    )
    return True


def with_noise_std(observer: Any, sigma: float) -> Any:
    """``observer`` built with ``noise_std = sigma`` (not reset), or ``None`` if that changes
    none of its options.  Families whose gains ignore σ (``noise_in_gains = False``) use it
    only in ``_sigma2``, the measurement variance of their NIS: a copy with that replaced (no
    costly rebuild)."""
    if not observer.noise_in_gains:
        twin = copy.copy(observer)
        twin.noise_std = sigma
        twin._sigma2 = twin.noise_std_used**2  # the family's NIS measurement variance
        return twin
    args, kwargs = observer._init_args
    fresh = type(observer)(*args, **{**kwargs, "noise_std": sigma})
    options = {k: v for k, v in fresh.options.items() if k != "noise_std"}
    return (
        None
        if options == {k: v for k, v in observer.options.items() if k != "noise_std"}
        else fresh
    )
