"""One palette for every picture of a run: the playback's ghosts and chart, and the PNG plots.

Observer ``i`` of a run (in run order) gets ``PALETTE[i]`` everywhere.  The
first seven colours are Okabe and Ito's colour-blind-safe set (Okabe & Ito,
*Color Universal Design*, 2008; their eighth colour, black, is kept for the
truth's curves); the last three are from matplotlib's ``tab10`` (purple,
brown, olive).  Any two of the ten are at least 60 apart in RGB (0–255 per
channel, Euclidean distance); after ten the colours repeat.

The truth's body keeps the robot model's colours, so :func:`observer_colours`
skips the palette colours that are closer than that to one of them (a blue
ghost next to the cart-pole's blue pole would read as the truth).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["MIN_DISTANCE", "PALETTE", "TRUTH_LINE", "colour", "hex_colour", "observer_colours"]

#: Observer colours in run order: (name, RGB in [0, 1]).
PALETTE: tuple[tuple[str, tuple[float, float, float]], ...] = tuple(
    (name, (r / 255.0, g / 255.0, b / 255.0))
    for name, (r, g, b) in (
        ("vermillion", (213, 94, 0)),  # Okabe–Ito
        ("blue", (0, 114, 178)),
        ("bluish green", (0, 158, 115)),
        ("orange", (230, 159, 0)),
        ("reddish purple", (204, 121, 167)),
        ("sky blue", (86, 180, 233)),
        ("yellow", (240, 228, 66)),
        ("purple", (148, 103, 189)),  # tab10
        ("brown", (140, 86, 75)),
        ("olive", (188, 189, 34)),
    )
)

#: Smallest RGB distance (0–255 per channel) between two palette colours, and
#: between an observer's colour and the truth's model colours.
MIN_DISTANCE = 60.0

#: Colour of the truth's curves in the plots and the playback chart (its 3-D
#: body keeps the model's own colours).
TRUTH_LINE = "#000000"


def colour(i: int) -> tuple[str, tuple[float, float, float]]:
    """Name and RGB in [0, 1] of observer ``i`` (run order; repeats after ten)."""
    return PALETTE[i % len(PALETTE)]


def hex_colour(rgb: Sequence[float]) -> str:
    """CSS ``#rrggbb`` of an RGB triple in [0, 1]."""
    return "#" + "".join(f"{round(255 * float(c)):02x}" for c in rgb[:3])


def observer_colours(
    n: int, avoid: Sequence[str] = ()
) -> list[tuple[str, tuple[float, float, float]]]:
    """Name and RGB of ``n`` observers in order: the palette without the colours closer
    than :data:`MIN_DISTANCE` to any of ``avoid`` (CSS ``#rrggbb``, e.g. the truth's
    model colours), repeating after the last one."""
    far = [
        (name, rgb)
        for name, rgb in PALETTE
        if all(_distance(hex_colour(rgb), a) >= MIN_DISTANCE for a in avoid)
    ] or list(PALETTE)
    return [far[i % len(far)] for i in range(n)]


def _distance(a: str, b: str) -> float:
    """Euclidean RGB distance of two ``#rrggbb`` colours (0–255 per channel)."""
    pa = [int(a[i : i + 2], 16) for i in (1, 3, 5)]
    pb = [int(b[i : i + 2], 16) for i in (1, 3, 5)]
    return float(sum((x - y) ** 2 for x, y in zip(pa, pb, strict=True)) ** 0.5)
