"""One result type for every simulation: fixed shapes, time first, read-only arrays."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pinobs.errors import LogFormatError, ModelFileError, UnknownNameError
from pinobs.model.robot import Vector, read_only

__all__ = ["RESULT_FORMAT", "ObserverTrace", "Result"]

#: Version of the ``.npz`` layout :meth:`Result.save` writes (``header["format"]``);
#: :meth:`Result.load` reads it and every older one (files without it are version 1)
#: and refuses a newer one.
RESULT_FORMAT = 1


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
            "format": RESULT_FORMAT,
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
        """Read a result written by :meth:`save`.

        Raises:
            ModelFileError: no such file.
            LogFormatError: the file is not a saved result (not an ``.npz``, no header,
                arrays missing) or was written by a newer pinobs (its format version).
        """
        path = Path(path)
        if not path.is_file():
            raise ModelFileError(f"result file {str(path)!r} does not exist")
        what = f"{str(path)!r} is not a result saved by pinobs (Result.save, pinobs run --save)"
        try:
            with np.load(path, allow_pickle=False) as z:
                if not hasattr(z, "files") or "header" not in z.files:
                    raise LogFormatError(f"{what}: it has no header")
                header = json.loads(str(z["header"]))
                version = header.get("format", 1) if isinstance(header, dict) else None
                if not isinstance(version, int) or isinstance(version, bool):
                    raise LogFormatError(f"{what}: its header is not a result's")
                if version > RESULT_FORMAT:
                    raise LogFormatError(
                        f"{str(path)!r} was saved in result format {version}; this pinobs "
                        f"reads formats up to {RESULT_FORMAT}: upgrade pinobs to read it"
                    )
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
                result = cls(
                    robot=header["robot"],
                    t=z["t"],
                    q=z["q"],
                    v=z["v"],
                    tau=z["tau"],
                    q_meas=z["q_meas"],
                    traces=traces,
                    meta=header["meta"],
                )
        except LogFormatError:
            raise
        except (KeyError, TypeError, IndexError) as exc:
            raise LogFormatError(f"{what}: {type(exc).__name__} {exc}") from None
        except (ValueError, OSError, zipfile.BadZipFile, EOFError):  # not an .npz
            raise LogFormatError(f"{what}: it is not an .npz archive") from None
        if result.t.ndim != 1 or any(
            a.shape[0] != result.t.shape[0] for a in (result.q, result.v, result.tau)
        ):
            raise LogFormatError(f"{what}: its arrays do not have one row per time")
        return result
