"""NPZ logs (arrays ``t``, ``q``, ``tau``; a saved result read as what its sensor measured)."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from pinobs.errors import DimensionError, LogFormatError
from pinobs.io.readers.layout import lock_hint
from pinobs.io.readers.log import Log
from pinobs.model import Robot


def npz_log(path: Path, robot: Robot) -> Log:
    try:
        with path.open("rb") as fh:
            loaded = np.load(io.BytesIO(fh.read()), allow_pickle=False)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
        raise LogFormatError(
            f"log {str(path)!r} is not a readable .npz archive ({type(exc).__name__}: {exc}); "
            "a truncated copy? write one with np.savez(path, t=..., q=..., tau=...)"
        ) from None
    if isinstance(loaded, np.ndarray):
        raise LogFormatError(
            f"log {str(path)!r} holds one .npy array of shape {loaded.shape}, not an .npz "
            "archive with arrays t, q (and tau): write one with np.savez(path, t=..., q=..., tau=...)"
        )
    with loaded as z:
        keys = list(z.keys())
        if "t" not in keys or "q" not in keys:
            raise LogFormatError(
                f"log {str(path)!r} has arrays {keys}; a log needs t, q (and optionally tau)"
            )
        try:
            t = np.asarray(z["t"], dtype=float)
            # a saved simulation result: what its sensor measured, not the truth
            q_name = "q_meas" if "q_meas" in keys else "q"
            q = np.asarray(z[q_name], dtype=float)
            tau = np.asarray(z["tau"], dtype=float) if "tau" in keys else None
        except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
            raise LogFormatError(
                f"log {str(path)!r}: an array cannot be read ({type(exc).__name__}: {exc}); "
                "a truncated copy?"
            ) from None
    if (
        t.ndim != 1
        or q.shape != (t.size, robot.nq)
        or (tau is not None and tau.shape != (t.size, robot.nv))
    ):
        raise DimensionError(
            f"log {str(path)!r}: t {t.shape}, {q_name} {q.shape}, "
            f"tau {None if tau is None else tau.shape}; "
            f"robot {robot.name!r} needs {q_name} of shape (N, {robot.nq}) and tau of shape "
            f"(N, {robot.nv})"
            + (" (q_meas is read as the log's q when present)" if q_name != "q" else "")
            + (
                lock_hint(
                    [b.name for b in robot.joints if b.idx_q + b.nq > q.shape[1]],
                    robot.joint_names,
                )
                if q.ndim == 2 and 0 < q.shape[1] < robot.nq
                else ""
            )
        )
    return Log(t=t, q=q, tau=tau, unit="row")
