"""One result type for every simulation: fixed shapes, time first, read-only arrays."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import ModelFileError, UnknownNameError
from pinobs.model.robot import Vector, read_only

__all__ = ["ObserverTrace", "Result"]


@dataclass(frozen=True)
class ObserverTrace:
    """What one observer estimated along a run.

    Attributes:
        name: label of the observer in this run (registry name unless renamed).
        q: estimated configurations, shape ``(N, nq)``; NaN after a divergence.
        v: estimated velocities, shape ``(N, nv)``; NaN after a divergence.
        update_time: wall time of each ``update`` call [s], shape ``(N,)``
            (entry 0 is the ``reset`` call; NaN after a divergence).
        options: the observer's resolved options (gains included).
        diverged_at: time of an ``ObserverDiverged`` [s], or ``None``.
    """

    name: str
    q: Vector
    v: Vector
    update_time: Vector
    options: dict[str, Any] = field(default_factory=dict)
    diverged_at: float | None = None

    def __post_init__(self) -> None:
        for k in ("q", "v", "update_time"):
            object.__setattr__(self, k, read_only(getattr(self, k)))


@dataclass(frozen=True)
class Result:
    """A simulation run: the truth, the measurements and every observer's estimates.

    Attributes:
        robot: robot name.
        t: sample times [s], shape ``(N,)``.
        q, v: true configuration ``(N, nq)`` and velocity ``(N, nv)`` at the samples.
        tau: torque applied from each sample on ``(N, nv)``.
        q_meas: measurements ``(N, nq)``; a row of NaN where the sample was dropped.
        traces: one :class:`ObserverTrace` per observer, in run order.
        meta: run settings (rate, noise, seed, input, duration, perturbation, ...).
    """

    robot: str
    t: Vector
    q: Vector
    v: Vector
    tau: Vector
    q_meas: Vector
    traces: tuple[ObserverTrace, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for k in ("t", "q", "v", "tau", "q_meas"):
            object.__setattr__(self, k, read_only(getattr(self, k)))

    @property
    def observer_names(self) -> list[str]:
        """Labels of the observers, in run order."""
        return [tr.name for tr in self.traces]

    def trace(self, name: str) -> ObserverTrace:
        """The trace of observer ``name``."""
        for tr in self.traces:
            if tr.name == name:
                return tr
        raise UnknownNameError(f"no observer {name!r} in this result; have {self.observer_names}")

    def save(self, path: str | Path) -> Path:
        """Write the result to a ``.npz`` file; :meth:`load` reads it back."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, Any] = {k: getattr(self, k) for k in ("t", "q", "v", "tau", "q_meas")}
        header = {
            "robot": self.robot,
            "meta": self.meta,
            "traces": [
                {"name": tr.name, "options": tr.options, "diverged_at": tr.diverged_at}
                for tr in self.traces
            ],
        }
        for i, tr in enumerate(self.traces):
            arrays[f"trace{i}_q"] = tr.q
            arrays[f"trace{i}_v"] = tr.v
            arrays[f"trace{i}_update_time"] = tr.update_time
        arrays["header"] = np.array(json.dumps(header, default=float))
        with path.open("wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Result:
        """Read a result written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise ModelFileError(f"result file {str(path)!r} does not exist")
        with np.load(path, allow_pickle=False) as z:
            header = json.loads(str(z["header"]))
            traces = tuple(
                ObserverTrace(
                    name=h["name"],
                    q=z[f"trace{i}_q"],
                    v=z[f"trace{i}_v"],
                    update_time=z[f"trace{i}_update_time"],
                    options=h["options"],
                    diverged_at=h["diverged_at"],
                )
                for i, h in enumerate(header["traces"])
            )
            return cls(
                robot=header["robot"],
                t=z["t"],
                q=z["q"],
                v=z["v"],
                tau=z["tau"],
                q_meas=z["q_meas"],
                traces=traces,
                meta=header["meta"],
            )
