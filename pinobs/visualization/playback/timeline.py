"""The playback's timeline: which samples are shown, at how many keyframes per second,
and the stretches without a finite configuration.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pinobs.errors import DimensionError, GainError
from pinobs.model.robot import Vector

__all__ = [
    "MAX_ANIMATION_BYTES",
    "budget_note",
    "forward_fill",
    "frame_indices",
    "gap_stretches",
    "keyframe_rate",
]


#: Bytes of a page the animation's keyframes may take [B]: a longer run gets fewer
#: keyframes per second (meshcat interpolates between them), and a warning says so.
MAX_ANIMATION_BYTES = 8_000_000
#: Page bytes of one node's keyframe at most: position and quaternion, each a msgpack map
#: ``{time: frame < 2**32, value: [float64, ...]}`` (45 + 54 B), base64-encoded (x 4/3).
_KEY_BYTES = 132
#: Page bytes of one node's clip without its keys, at most (path, names, types; base64).
_CLIP_BYTES = 400


def frame_indices(t: Vector, fps: float) -> Vector:
    """Indices of the samples shown at ``fps`` frames per second of simulated time.

    Frame ``k`` shows the sample nearest to ``t[0] + k / fps``; the last frame
    is the last sample.
    """
    t = np.asarray(t, dtype=float)
    if not (math.isfinite(fps) and fps > 0):
        raise GainError(f"fps={fps!r} must be a positive frame rate [1/s], e.g. 30")
    if t.ndim != 1 or t.size == 0:
        raise DimensionError(f"t must be a non-empty 1-D array of times, got shape {t.shape}")
    n = max(1, math.floor((t[-1] - t[0]) * fps + 1e-9) + 1)
    want = t[0] + np.arange(n) / fps
    idx = np.clip(np.searchsorted(t, want), 0, t.size - 1)
    left = np.clip(idx - 1, 0, t.size - 1)
    idx = np.where(np.abs(t[left] - want) <= np.abs(t[idx] - want), left, idx)
    return idx.astype(int)


def forward_fill(q: Vector, fallback: Vector) -> Vector:
    """Rows with NaN (after a divergence) replaced by the last finite row (or ``fallback``)."""
    out = np.array(q, dtype=float)
    last = fallback
    for k in range(out.shape[0]):
        if np.all(np.isfinite(out[k])):
            last = out[k]
        else:
            out[k] = last
    return out


def gap_stretches(t: Vector, ok: NDArray[np.bool_]) -> tuple[tuple[float, float], ...]:
    """Stretches ``(start, end)`` [s] of rows not ``ok``: from the first such row to the next ok
    row (the last row for a stretch running to the end)."""
    d = np.diff(np.concatenate([[0], (~ok).astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    last = len(t) - 1
    return tuple(
        (float(t[a]), float(t[min(int(b), last)])) for a, b in zip(starts, ends, strict=True)
    )


def keyframe_rate(t: Vector, fps: float, nodes: int) -> float:
    """``fps``, or the lower rate at which the keyframes of ``nodes`` animated nodes fit
    :data:`MAX_ANIMATION_BYTES` [1/s]."""
    wanted = len(frame_indices(t, fps))  # (checks fps)
    fit = max(2, (MAX_ANIMATION_BYTES - _CLIP_BYTES * nodes) // (_KEY_BYTES * nodes))
    if wanted <= fit:
        return fps
    return (fit - 1) / float(t[-1] - t[0])


def budget_note(t: Vector, rate: float, fps: float) -> str:
    """What the page and a warning say when the keyframes come at ``rate`` instead of ``fps``
    [1/s] to fit :data:`MAX_ANIMATION_BYTES` (:func:`keyframe_rate`)."""
    return (
        f"keyframes at {rate:.3g} per second instead of {fps:g}: the "
        f"{t[-1] - t[0]:.4g} s run fits the page's animation budget "
        f"({MAX_ANIMATION_BYTES / 1e6:g} MB), motion between keyframes interpolated"
    )
