"""Meshcat playback of a run: the true robot and each observer's estimate as a ghost.

The truth is drawn as the model describes it (URDF colours and meshes, loaded
by :class:`pinocchio.visualize.MeshcatVisualizer`); each observer's estimate
``q̂(t)`` is a translucent ghost of the same robot in its own colour
(:func:`pinobs.visualization.palette.observer_colours`: a colour-blind-safe
palette, away from the robot's own colours; the plots use the same).
Robots without visual geometry get a stick figure (a sphere per joint, a rod
per link).  A floor grid lies on the plane ``z = 0`` under the motion.  A
floating base (free-flyer or planar root) is followed: the scene, floor
included, moves so that the true base stays in view.  The motion is
one meshcat ``Animation`` keyframed at ``fps``
frames per second of simulated time, so meshcat's own timeline (Open Controls
→ Animations: play, pause, reset, time slider, time scale) plays, pauses and
scrubs it.  The keyframes take at most :data:`MAX_ANIMATION_BYTES` (8 MB) of
a page: a long run gets fewer keyframes per second, and says so.  Rows
without a finite configuration are not drawn: the truth holds its last pose,
a ghost is hidden, and the legend says when.

Two ways to watch:

* :func:`write_html` writes one self-contained HTML file (meshcat's viewer,
  the scene and the animation embedded; no network needed).  Scene commands
  are recorded in-process by a window object standing in for meshcat's
  server, and ``Visualizer.static_html()`` turns them into the page, so no
  server is started and no port is opened.  The page shows a legend (an HTML
  overlay, top left: the truth in its model colours and one colour swatch per
  observer), the current time, and under the 3-D view a chart of true against
  estimated velocity whose cursor follows the animation
  (:mod:`pinobs.visualization.chart`).  Opening it as ``file.html#t=1.5`` pauses the animation at
  ``t = 1.5 s`` (used by the tests to screenshot two instants); ``#paused``
  opens it paused at the start, ``&nolegend`` hides the legend.
* :func:`serve` sends the same scene to a live meshcat server (started on
  127.0.0.1 by ``meshcat.Visualizer()``) and prints its URL.
"""

from __future__ import annotations

import base64
import functools
import html
import json
import math
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pinobs.errors import (
    DimensionError,
    GainError,
    NonFiniteError,
    PinobsWarning,
    UnknownNameError,
)
from pinobs.io import Log, LogRun
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.simulation import ObserverTrace, Result
from pinobs.visualization._deps import require
from pinobs.visualization.axes import slide_axis
from pinobs.visualization.chart import chart_data, chart_html
from pinobs.visualization.palette import hex_colour, observer_colours

__all__ = [
    "MAX_ANIMATION_BYTES",
    "LegendEntry",
    "LiveViewer",
    "build_scene",
    "frame_indices",
    "log_result",
    "serve",
    "truth_colours",
    "write_html",
    "write_html_from_file",
]

#: Opacity of a ghost (0 invisible, 1 opaque).
GHOST_OPACITY = 0.5

_BACKGROUND = [1.0, 1.0, 1.0]
_CAMERA_FOV_DEG = 75.0  # meshcat's default perspective camera (vertical field of view)
_REPEAT = 1_000_000  # "loop forever": THREE.LoopRepeat needs a finite count
#: Mesh files (Collada, STL, OBJ) up to this total size are sent as they are
#: for the truth; above it the truth gets the same decimated triangles as the ghosts.
_MAX_MESH_FILE_BYTES = 4_000_000
#: Bytes of a page the animation's keyframes may take [B]: a longer run gets fewer
#: keyframes per second (meshcat interpolates between them), and a warning says so.
MAX_ANIMATION_BYTES = 8_000_000
#: Page bytes of one node's keyframe at most: position and quaternion, each a msgpack map
#: ``{time: frame < 2**32, value: [float64, ...]}`` (45 + 54 B), base64-encoded (x 4/3).
_KEY_BYTES = 132
#: Page bytes of one node's clip without its keys, at most (path, names, types; base64).
_CLIP_BYTES = 400

#: ``progress(k, n)`` is called after frame ``k`` of ``n`` (as in :func:`pinobs.simulate`).
Progress = Callable[[int, int], None]


def _int_colour(rgb: Sequence[float]) -> int:
    """``0xRRGGBB`` of an RGB triple in [0, 1] (meshcat's material colour)."""
    r, g, b = (round(255 * float(c)) for c in rgb[:3])
    return r * 65536 + g * 256 + b


@dataclass(frozen=True)
class LegendEntry:
    """One line of the legend.

    Attributes:
        label: observer label (or ``"truth"``).
        colour: CSS colour (``#rrggbb``) of its swatch, or ``None`` for the truth's own colours.
        colour_name: human name of the colour (``"model colours"`` for the truth).
        node: meshcat path of its scene node under ``/meshcat``.
        diverged_at: time of divergence [s], or ``None``.
        model_colours: for the truth, the CSS colours its body renders in (the
            visual model's ``meshColor``, most used first); empty for a ghost.
        gaps: stretches ``(start, end)`` [s] without a finite configuration (NaN
            rows: dropped samples, a divergence), from the first such row to the
            next finite one: the truth holds its last pose, a ghost is hidden.
    """

    label: str
    colour: str | None
    colour_name: str
    node: str
    diverged_at: float | None = None
    model_colours: tuple[str, ...] = ()
    gaps: tuple[tuple[float, float], ...] = ()

    @property
    def gap_note(self) -> str:
        """The gaps in words (empty without gaps), e.g. ``"no data 0.3–0.5 s: pose held"``."""
        if not self.gaps:
            return ""
        what = "no data" if self.colour is None else "no estimate"
        shown = "pose held" if self.colour is None else "hidden"
        a, b = self.gaps[0][0], self.gaps[-1][1]
        if self.diverged_at is not None and len(self.gaps) == 1 and a >= self.diverged_at:
            return f"hidden from {a:.3g} s"
        if len(self.gaps) == 1:
            return f"{what} {a:.3g}–{b:.3g} s: {shown}"
        lost = sum(e - s for s, e in self.gaps)
        return (
            f"{what} in {len(self.gaps)} stretches between {a:.3g} and {b:.3g} s "
            f"({lost:.3g} s in all): {shown}"
        )


def _model_colours(
    geom: pin.GeometryModel, *, collada_materials: bool, most: int = 3
) -> tuple[str, ...]:
    """The ``most`` colours the truth is drawn in, by number of geometries.

    A geometry is painted in its ``meshColor``, except a Collada file sent as
    it is (``collada_materials``: Pinocchio's visualizer, without
    ``overrideMaterial``), which keeps its own materials: their diffuse colours
    are read from the file.
    """
    counts: dict[str, int] = {}
    for go in geom.geometryObjects:
        found: list[str] = []
        path = Path(go.meshPath) if go.meshPath else None
        if (
            collada_materials
            and not go.overrideMaterial
            and path is not None
            and path.suffix.lower() == ".dae"
            and path.is_file()
        ):
            text = path.read_text(encoding="utf-8", errors="replace")
            for m in re.finditer(r"<diffuse>\s*<color[^>]*>([^<]+)</color>", text):
                rgb = [float(x) for x in m.group(1).split()[:3]]
                found.append(hex_colour([min(max(c, 0.0), 1.0) for c in rgb]))
        for key in found or [hex_colour(go.meshColor[:3])]:
            counts[key] = counts.get(key, 0) + 1
    ranked = sorted(counts, key=lambda k: -counts[k])
    return tuple(ranked[:most])


def truth_colours(robot: Robot) -> tuple[str, ...]:
    """CSS colours the truth's body renders in, in a playback of ``robot`` (most used first);
    observers' colours keep away from them (:func:`~pinobs.visualization.palette.observer_colours`)."""
    geom = _visual_model(robot)
    return _model_colours(geom, collada_materials=_mesh_file_bytes(geom) <= _MAX_MESH_FILE_BYTES)


# ----------------------------------------------------------------- recording


class _RecordingWindow:
    """Stand-in for meshcat's ``ViewerWindow``: records commands instead of sending them.

    ``meshcat.Visualizer(window=_RecordingWindow(...))`` behaves like a
    visualizer connected to a server; :meth:`get_scene` (what
    ``Visualizer.static_html()`` calls) returns the standalone page with every
    recorded command replayed in order.
    """

    web_url: str | None = None

    def __init__(self, overlay: str = "") -> None:
        self.commands: list[bytes] = []
        self.overlay = overlay

    def send(self, command: Any) -> None:
        umsgpack = require("umsgpack", "meshcat playback")
        data = command.lower()
        self.commands.append(umsgpack.packb(data))

    def get_scene(self) -> str:
        viewer_js = _viewer_js()
        cmds = ",\n".join(f'"{base64.b64encode(c).decode("ascii")}"' for c in self.commands)
        return _fill("page.html", mainminjs=viewer_js, commands=cmds, overlay=self.overlay)

    def open(self) -> _RecordingWindow:
        return self

    def close(self) -> None:
        return None


def _viewer_js() -> str:
    meshcat = require("meshcat", "meshcat playback")
    path = Path(str(meshcat.__file__)).parent / "viewer" / "dist" / "main.min.js"
    return path.read_text(encoding="utf-8")


_SLOT = re.compile(r"@([A-Z][A-Z0-9_]*)@")


@functools.cache
def _template(name: str) -> str:
    """The text of ``templates/<name>``, shipped as package data."""
    return (resources.files(__name__) / "templates" / name).read_text(encoding="utf-8")


def _fill(name: str, **values: str) -> str:
    """Template ``name`` with each slot ``@KEY@`` replaced by ``values["key"]``, in one pass
    (what a value holds is not read for slots).

    The templates: ``page.html``, the page meshcat's server builds for
    ``static_html()``, with the commands replayed synchronously (meshcat's own
    page fetches ``data:`` URLs, in no guaranteed order) and our overlay added
    (``"</script"`` cannot occur in base64 or in ``main.min.js``' string
    literals used there); ``legend.html`` and ``legend.js``, the legend overlay.
    """
    text = _template(name)
    slots = {m.lower() for m in _SLOT.findall(text)}
    if slots != set(values):
        raise KeyError(f"template {name} has slots {sorted(slots)}, given {sorted(values)}")
    return _SLOT.sub(lambda m: values[m.group(1).lower()], text)


def _overlay(
    title: str,
    entries: Sequence[LegendEntry],
    t0: float,
    t_end: float,
    notes: Sequence[str] = (),
) -> str:
    rows = []
    for e in entries:
        if e.colour is None:
            cs = e.model_colours or ("#cccccc",)
            stops = ",".join(
                f"{c} {100 * k / len(cs):.0f}% {100 * (k + 1) / len(cs):.0f}%"
                for k, c in enumerate(cs)
            )
            swatch = (
                '<span style="display:inline-block;width:12px;height:12px;margin-right:6px;'
                f'border:1px solid #555;background:linear-gradient(135deg,{stops})"></span>'
            )
        else:
            swatch = (
                '<span style="display:inline-block;width:12px;height:12px;margin-right:6px;'
                f'border:1px solid #555;background:{e.colour};opacity:0.8"></span>'
            )
        said = [f"diverged at {e.diverged_at:.3g} s"] if e.diverged_at is not None else []
        said += [e.gap_note] if e.gaps else []
        note = f" ({'; '.join(said)})" if said else ""
        what = "estimate"
        if e.colour is None:
            what = "true motion" if e.label == "truth" else "recorded motion"
        now = "no data now: pose held" if e.colour is None else "no estimate now: hidden"
        rows.append(
            f'<div class="pinobs-entry" data-label="{html.escape(e.label)}">{swatch}'
            f"<b>{html.escape(e.label)}</b> · {what}{html.escape(note)}"
            f'<span class="pinobs-gap" style="display:none;color:#b00"> · {now}</span></div>'
        )
    gaps = json.dumps([[[round(a, 6), round(b, 6)] for a, b in e.gaps] for e in entries])
    script = _fill("legend.js", t0=repr(float(t0)), t_end=repr(float(t_end)), gaps=gaps)
    return _fill(
        "legend.html",
        title=html.escape(title),
        rows="\n".join(rows),
        time=f"{float(t0):.2f}",
        notes="".join(
            f'<div class="pinobs-note" style="color:#666;font-size:11px">{html.escape(n)}</div>\n'
            for n in notes
        ),
        script=script,
    )


# ------------------------------------------------------------------ geometry


def _stick_figure(
    model: pin.Model, travel: Mapping[int, tuple[float, float]] | None = None
) -> pin.GeometryModel:
    """Simple shapes for a robot without visual geometry: a sphere per joint, a rod per link,
    and a rail per prismatic joint.

    The rod to a joint is fixed in its parent's frame and ends where the joint is at
    ``q = 0``; a prismatic joint moves away from there, along a thinner rail that spans
    ``travel[joint_id]`` (its lowest and highest position [m] in the motion shown), else its
    finite limits, else one link length either way, and ``0`` in any case: the figure stays
    connected however far it slides.
    """
    coal = require("coal", "stick figures of robots without meshes")
    geom = pin.GeometryModel()
    lengths = [
        float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(1, model.njoints)
    ]
    scale = max([x for x in lengths if x > 1e-6], default=0.5)
    radius = max(0.02, 0.08 * scale)
    for j in range(1, model.njoints):
        name = model.names[j]
        geom.addGeometryObject(
            pin.GeometryObject(f"{name}_joint", j, pin.SE3.Identity(), coal.Sphere(radius))
        )
        parent = model.parents[j]
        offset = model.jointPlacements[j].translation
        length = float(np.linalg.norm(offset))
        if parent > 0 and length > 1e-6:
            # a rod from the parent joint to this one, in the parent's frame
            axis = offset / length
            rot = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).toRotationMatrix()
            placement = pin.SE3(rot, 0.5 * offset)
            geom.addGeometryObject(
                pin.GeometryObject(
                    f"{name}_rod", parent, placement, coal.Cylinder(0.4 * radius, length)
                )
            )
        axis = slide_axis(model, j)
        if axis is not None:
            lo, hi = _rail(model, j, scale, (travel or {}).get(j))
            rot = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).toRotationMatrix()
            placement = model.jointPlacements[j] * pin.SE3(rot, 0.5 * (lo + hi) * axis)
            geom.addGeometryObject(
                pin.GeometryObject(
                    f"{name}_rail", parent, placement, coal.Cylinder(0.25 * radius, hi - lo)
                )
            )
        leaf = j not in model.parents[j + 1 :]
        tip = 2.0 * model.inertias[j].lever
        if leaf and np.linalg.norm(tip) > 1e-6:  # the last link: a rod through its centre of mass
            rot = pin.Quaternion.FromTwoVectors(
                np.array([0.0, 0.0, 1.0]), tip / np.linalg.norm(tip)
            ).toRotationMatrix()
            geom.addGeometryObject(
                pin.GeometryObject(
                    f"{name}_tip",
                    j,
                    pin.SE3(rot, 0.5 * tip),
                    coal.Cylinder(0.4 * radius, float(np.linalg.norm(tip))),
                )
            )
    for go in geom.geometryObjects:
        go.meshColor = np.array([0.45, 0.45, 0.5, 1.0])
    return geom


def _rail(
    model: pin.Model, joint_id: int, scale: float, shown: tuple[float, float] | None
) -> tuple[float, float]:
    """Ends [m] of a prismatic joint's rail: ``shown`` (the positions played back), else the
    joint's finite limits, else ``±scale``; always holding 0 and at least ``scale / 10`` long."""
    k = model.joints[joint_id].idx_q
    limits = (float(model.lowerPositionLimit[k]), float(model.upperPositionLimit[k]))
    if shown is not None:
        lo, hi = shown
    elif all(math.isfinite(x) and abs(x) < 1e3 for x in limits):
        lo, hi = limits
    else:
        lo, hi = -scale, scale
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    if hi - lo < 0.1 * scale:
        lo, hi = lo - 0.05 * scale, hi + 0.05 * scale
    return lo, hi


def _travel(robot: Robot, configurations: Sequence[Vector]) -> dict[int, tuple[float, float]]:
    """Lowest and highest finite position [m] of each prismatic joint in ``configurations``
    (arrays of rows of ``q``)."""
    out = {}
    model = robot.model
    for j in range(1, model.njoints):
        if slide_axis(model, j) is None:
            continue
        k = model.joints[j].idx_q
        x = np.concatenate([np.asarray(q, dtype=float)[:, k] for q in configurations])
        x = x[np.isfinite(x)]
        if x.size:
            out[j] = (float(x.min()), float(x.max()))
    return out


def _visual_model(robot: Robot, configurations: Sequence[Vector] = ()) -> pin.GeometryModel:
    """The robot's visual geometry, or a stick figure whose prismatic rails span the
    ``configurations`` (rows of ``q``) played back."""
    vm = robot.visual_model
    if vm is None or vm.ngeoms == 0:
        return _stick_figure(
            robot.model, _travel(robot, configurations) if configurations else None
        )
    return vm


def _decimate(
    vertices: Vector, faces: NDArray[np.int64], max_triangles: int
) -> tuple[Vector, NDArray[np.int64]]:
    """Vertex clustering: merge vertices on a grid until at most ``max_triangles`` remain.

    The grid cell starts at 1/400 of the mesh's bounding-box diagonal and
    doubles until the budget is met; degenerate and repeated triangles are
    dropped.  Shapes keep their outline (what a playback needs), not their detail.
    """
    if len(faces) <= max_triangles:
        return vertices, faces
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    cell = float(np.linalg.norm(hi - lo)) / 400.0 or 1e-3
    while True:
        keys = np.floor((vertices - lo) / cell).astype(np.int64)
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        merged = np.zeros((counts.size, 3))
        np.add.at(merged, inverse, vertices)
        merged /= counts[:, None]
        f = inverse[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
        f = f[np.sort(first)]
        if len(f) <= max_triangles:
            return merged, f
        cell *= 2.0


def _triangles(go: pin.GeometryObject) -> tuple[Vector, NDArray[np.int64]] | None:
    """Vertices (already scaled by ``meshScale``) and triangles of a mesh geometry, or ``None``."""
    coal = require("coal", "meshcat playback")
    g = go.geometry
    if isinstance(g, coal.BVHModelBase) and g.num_tris > 0:
        vertices = np.array(g.vertices(), dtype=float)
        faces = np.array(
            [[t[0], t[1], t[2]] for t in (g.tri_indices(k) for k in range(g.num_tris))],
            dtype=np.int64,
        )
        if np.prod(go.meshScale) < 0:  # a mirrored mesh: restore outward winding
            faces = faces[:, [0, 2, 1]]
        return vertices, faces
    if isinstance(g, coal.Convex) and g.num_polygons > 0:
        vertices = np.array(g.points(), dtype=float)
        faces = np.array(
            [[t[0], t[1], t[2]] for t in (g.polygons(k) for k in range(g.num_polygons))],
            dtype=np.int64,
        )
        return vertices, faces
    return None


def _mesh_file_bytes(geom: pin.GeometryModel) -> int:
    total = 0
    for go in geom.geometryObjects:
        p = Path(go.meshPath) if go.meshPath else None
        if p is not None and p.suffix.lower() in (".dae", ".stl", ".obj") and p.is_file():
            total += p.stat().st_size
    return total


def _bounding_radius(go: pin.GeometryObject) -> float:
    geometry = go.geometry
    try:
        geometry.computeLocalAABB()
        r = float(geometry.aabb_radius) + float(np.linalg.norm(geometry.aabb_center))
    except (AttributeError, RuntimeError):
        return 0.05
    return r * float(np.max(np.abs(go.meshScale))) if np.isfinite(r) else 0.05


# -------------------------------------------------------------------- frames


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


def _forward_fill(q: Vector, fallback: Vector) -> Vector:
    """Rows with NaN (after a divergence) replaced by the last finite row (or ``fallback``)."""
    out = np.array(q, dtype=float)
    last = fallback
    for k in range(out.shape[0]):
        if np.all(np.isfinite(out[k])):
            last = out[k]
        else:
            out[k] = last
    return out


def _gaps(t: Vector, ok: NDArray[np.bool_]) -> tuple[tuple[float, float], ...]:
    """Stretches ``(start, end)`` [s] of rows not ``ok``: from the first such row to the next ok
    row (the last row for a stretch running to the end)."""
    d = np.diff(np.concatenate([[0], (~ok).astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    last = len(t) - 1
    return tuple(
        (float(t[a]), float(t[min(int(b), last)])) for a, b in zip(starts, ends, strict=True)
    )


def _keyframe_rate(t: Vector, fps: float, nodes: int) -> float:
    """``fps``, or the lower rate at which the keyframes of ``nodes`` animated nodes fit
    :data:`MAX_ANIMATION_BYTES` [1/s]."""
    wanted = len(frame_indices(t, fps))  # (checks fps)
    fit = max(2, (MAX_ANIMATION_BYTES - _CLIP_BYTES * nodes) // (_KEY_BYTES * nodes))
    if wanted <= fit:
        return fps
    return (fit - 1) / float(t[-1] - t[0])


def _placements(
    model: pin.Model, data: pin.Data, geom: pin.GeometryModel, gdata: pin.GeometryData, q: Vector
) -> list[pin.SE3]:
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, geom, gdata)
    return [gdata.oMg[i].copy() for i in range(geom.ngeoms)]


def _camera(points: Vector, radii: Vector) -> tuple[Vector, Vector]:
    """Target and camera offset [m] framing every point (with its radius) of the truth's motion."""
    lo = np.min(points - radii[:, None], axis=0)
    hi = np.max(points + radii[:, None], axis=0)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.2)
    spread = points - points.mean(axis=0)
    direction = np.array([1.0, -1.3, 0.8])
    if len(points) >= 3 and np.any(spread):
        _, s, vt = np.linalg.svd(spread, full_matrices=False)
        if s[-1] < 0.15 * s[0]:  # motion in a plane: look at the plane
            normal = vt[-1]
            if abs(normal[2]) > 0.9:  # horizontal plane: look from above, slightly tilted
                normal = np.sign(normal[2]) * normal + np.array([0.0, -0.4, 0.0])
            else:
                if normal @ np.array([0.2, -1.0, 0.0]) < 0:
                    normal = -normal
                normal = normal + np.array([0.0, 0.0, 0.35])
            direction = normal
    direction = direction / np.linalg.norm(direction)
    # the bounding sphere would just fit at R / sin(fov / 2); it overestimates boxes: go closer
    distance = 0.8 * radius / math.sin(math.radians(_CAMERA_FOV_DEG) / 2)
    return centre, distance * direction


# --------------------------------------------------------------------- scene


def _same(value: Any, _go: pin.GeometryObject) -> Any:
    return value


def _safe(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label) or "observer"


@dataclass(frozen=True)
class _Scene:
    legend: list[LegendEntry]
    fps: float  # keyframes per second used [1/s]
    notes: list[str]  # what the page says about its fidelity (a lowered keyframe rate)


def build_scene(
    vis: Any,
    result: Result,
    robot: Robot,
    *,
    fps: float = 30.0,
    observers: Sequence[str] | None = None,
    opacity: float = GHOST_OPACITY,
    play: bool = True,
    max_triangles: int = 60_000,
    truth_label: str = "truth",
    progress: Progress | None = None,
) -> list[LegendEntry]:
    """Load the truth and one ghost per observer into ``vis`` and animate them.

    Rows of ``result.q`` or of an estimate with NaN (dropped samples, a
    divergence) are not drawn: the truth holds its last finite pose, a ghost
    is hidden until its next finite row, and the legend entry's ``gaps`` (and
    the page, and a :class:`~pinobs.errors.PinobsWarning`) say when.

    The keyframes take at most :data:`MAX_ANIMATION_BYTES` of a page (8 MB):
    about 132 B per node per frame, a node being one geometry of the truth or
    of a ghost, so a long run (a UR5 with two ghosts: past 100 s) gets fewer
    than ``fps`` keyframes per second, meshcat interpolating between them; a
    :class:`~pinobs.errors.PinobsWarning` gives the rate used.

    Args:
        vis: a ``meshcat.Visualizer`` (live, or recording for :func:`write_html`).
        result: the run to play back.
        robot: the model the run used (``result.robot`` names it).
        fps: keyframes per second of simulated time [1/s], at most (see above).
        observers: labels to show (default: every observer of the run).
        opacity: ghost opacity in (0, 1].
        play: start playing when the page loads.
        max_triangles: triangle budget of one robot copy; larger meshes are
            decimated by vertex clustering (keeps files small: a Go1 is 3 MB
            instead of 115 MB).
        truth_label: legend name of ``result.q`` (``"measured"`` for a log).
        progress: called as ``progress(k, n)`` after frame ``k`` of ``n``.

    Returns:
        The legend: the truth, then one entry per ghost.

    Raises:
        DimensionError: the result's arrays do not fit ``robot``.
        NonFiniteError: no row of ``result.q`` is finite.
        UnknownNameError: an observer label is not in the result.
        GainError: ``fps`` or ``opacity`` out of range.
    """
    return _scene(
        vis,
        result,
        robot,
        fps=fps,
        observers=observers,
        opacity=opacity,
        play=play,
        max_triangles=max_triangles,
        truth_label=truth_label,
        progress=progress,
    ).legend


def _scene(
    vis: Any,
    result: Result,
    robot: Robot,
    *,
    fps: float,
    observers: Sequence[str] | None,
    opacity: float,
    play: bool = True,
    max_triangles: int = 60_000,
    truth_label: str = "truth",
    progress: Progress | None,
) -> _Scene:
    """:func:`build_scene`, also returning the keyframe rate used and the notes on fidelity."""
    viz_mod = require("pinocchio.visualize.meshcat_visualizer", "meshcat playback")
    mg = require("meshcat.geometry", "meshcat playback")
    animation = require("meshcat.animation", "meshcat playback")
    coal = require("coal", "meshcat playback")
    if result.q.shape[1:] != (robot.nq,):
        raise DimensionError(
            f"result of robot {result.robot!r} has q of shape {result.q.shape}, robot "
            f"{robot.name!r} has nq = {robot.nq}; play it back with the robot it was run on"
        )
    if not (0.0 < opacity <= 1.0):
        raise GainError(f"opacity={opacity!r} must be in (0, 1]")
    labels = list(result.observer_names if observers is None else observers)
    for name in labels:
        if name not in result.observer_names:
            raise UnknownNameError(
                f"no observer {name!r} in this result; have {result.observer_names}"
            )
    model = robot.model
    geom = _visual_model(robot, [result.q, *(result.trace(name).q for name in labels)])
    finite = np.all(np.isfinite(result.q), axis=1)
    if not finite.any():
        raise NonFiniteError(
            f"result of robot {result.robot!r}: none of its {len(finite)} configurations "
            "(rows of q) is finite; there is no motion to play back"
        )
    estimated = {name: np.all(np.isfinite(result.trace(name).q), axis=1) for name in labels}
    # A floating base (free-flyer, planar root) is followed: the scene moves so
    # that the true base stays in view; a fixed base is framed once.
    follow = bool(robot.joints) and robot.joints[0].kind in ("se3", "se2")
    # animated nodes: each geometry of each copy, a ghost's visibility, the followed scene
    rate = _keyframe_rate(result.t, fps, geom.ngeoms * (1 + len(labels)) + len(labels) + follow)
    idx = frame_indices(result.t, rate)
    notes = []
    if rate < fps:
        notes.append(
            f"keyframes at {rate:.3g} per second instead of {fps:g}: the "
            f"{result.t[-1] - result.t[0]:.4g} s run fits the page's animation budget "
            f"({MAX_ANIMATION_BYTES / 1e6:g} MB), motion between keyframes interpolated"
        )

    # Scene dressing: white background, no axes, camera framed on the truth.
    vis["/Background"].set_property("top_color", _BACKGROUND)
    vis["/Background"].set_property("bottom_color", _BACKGROUND)
    vis["/Axes"].set_property("visible", False)

    # Meshes are sent as (decimated) triangle lists, except the truth's mesh
    # files when they are small: those go through Pinocchio's visualizer as is
    # (textures and per-part colours of Collada files kept).
    meshes = {}
    for go in geom.geometryObjects:
        tri = _triangles(go) if not isinstance(go.geometry, coal.ShapeBase) else None
        if tri is not None:
            meshes[go.name] = tri
    total = sum(len(f) for _, f in meshes.values())
    for key, (v, f) in meshes.items():
        budget = max(200, int(max_triangles * len(f) / total)) if total > max_triangles else len(f)
        v, f = _decimate(v, f, budget)
        meshes[key] = (v, f)
    truth = viz_mod.MeshcatVisualizer(model, None, geom)
    truth.initViewer(viewer=vis)

    def load_copy(node: str, material_of: Callable[[pin.GeometryObject], Any]) -> None:
        for go in geom.geometryObjects:
            if isinstance(go.geometry, coal.ShapeBase):
                obj = truth.loadPrimitive(go)
            elif go.name in meshes:
                obj = mg.TriangularMeshGeometry(*meshes[go.name])  # meshScale already applied
            else:
                obj = None
            if obj is not None:
                vis[f"{node}/{go.name}"].set_object(obj, material_of(go))

    nodes: dict[str, list[str]] = {}
    scaled: dict[str, Vector] = {}
    as_is = _mesh_file_bytes(geom) <= _MAX_MESH_FILE_BYTES
    if as_is:
        # The truth, as the model describes it, through Pinocchio's visualizer.
        truth.loadViewerModel(rootNodeName="truth")
        nodes["truth"] = [f"truth/visuals/{go.name}" for go in geom.geometryObjects]
        # mesh-file objects drawn by Pinocchio carry meshScale in their node's scale
        scaled = {
            go.name: np.asarray(go.meshScale, dtype=float)
            for go in geom.geometryObjects
            if viz_mod.hasMeshFileInfo(go) and not isinstance(go.geometry, coal.ShapeBase)
        }
    else:
        load_copy(
            "truth",
            lambda go: mg.MeshPhongMaterial(color=_int_colour(go.meshColor[:3])),
        )
        nodes["truth"] = [f"truth/{go.name}" for go in geom.geometryObjects]
    truth_swatch = _model_colours(geom, collada_materials=as_is)
    legend = [
        LegendEntry(
            truth_label,
            None,
            "model colours",
            "truth",
            model_colours=truth_swatch,
            gaps=_gaps(result.t, finite),
        )
    ]
    colours = observer_colours(len(labels), truth_swatch)

    # Ghosts: the same shapes, one flat translucent colour each.
    for i, name in enumerate(labels):
        colour_name, rgb = colours[i]
        node = f"ghost_{i}_{_safe(name)}"
        # Front faces only, no depth writes, pushed slightly away from the camera:
        # the truth always shows in full, a ghost shows where it differs from the
        # truth and vanishes into it when it has converged; ghosts on each other
        # blend instead of z-fighting (mirrored meshes have their winding restored).
        material = mg.MeshPhongMaterial(
            color=_int_colour(rgb),
            transparent=opacity < 1.0,
            opacity=opacity,
            side=0,
            depthWrite=opacity >= 1.0,
            polygonOffset=True,
            polygonOffsetFactor=1.0,
            polygonOffsetUnits=4.0,
        )
        load_copy(node, functools.partial(_same, material))
        nodes[name] = [f"{node}/{go.name}" for go in geom.geometryObjects]
        tr = result.trace(name)
        legend.append(
            LegendEntry(
                name,
                hex_colour(rgb),
                colour_name,
                node,
                tr.diverged_at,
                gaps=_gaps(result.t, estimated[name]),
            )
        )
    # (a divergence is reported where it happens; the stretch after it needs no warning)
    told = [e for e in legend if e.gaps and not e.gap_note.startswith("hidden from")]
    for note in notes + [f"{e.label}: {e.gap_note}" for e in told]:
        warnings.warn(f"playback of {robot.name}: {note}", PinobsWarning, stacklevel=3)

    # Configurations shown, one row per frame: a NaN row holds the last finite one.
    first = result.q[np.argmax(finite)]
    shown = {"truth": _forward_fill(result.q, first)[idx]}
    present = {"truth": finite[idx]}
    for name in labels:
        shown[name] = _forward_fill(result.trace(name).q, first)[idx]
        present[name] = estimated[name][idx]

    data = model.createData()
    gdata = pin.GeometryData(geom)
    anim = animation.Animation(default_framerate=rate)
    points: list[Vector] = []
    radii_one = np.array([_bounding_radius(go) for go in geom.geometryObjects])
    radii: list[Vector] = []
    n_frames = len(idx)
    framed = present["truth"] if present["truth"].any() else np.ones(n_frames, dtype=bool)
    shift = np.zeros((n_frames, 3))
    total = n_frames * len(shown)
    done = 0
    for who, qs in shown.items():
        for k in range(n_frames):
            done += 1
            if progress is not None:
                progress(done, total)
            oMg = _placements(model, data, geom, gdata, qs[k])
            if who == "truth":
                if follow:
                    shift[k] = data.oMi[1].translation
                if framed[k]:  # the camera frames finite rows only
                    points.extend(M.translation - shift[k] for M in oMg)
                    radii.append(radii_one)
            if k == 0:  # a static pose too (with the mesh scale), for viewers without animation
                for go, path, M in zip(geom.geometryObjects, nodes[who], oMg, strict=True):
                    T = M.homogeneous
                    if who == "truth" and go.name in scaled:
                        T = T @ np.diag([*scaled[go.name], 1.0])
                    vis[path].set_transform(T)
            with anim.at_frame(vis, k) as frame:
                for path, M in zip(nodes[who], oMg, strict=True):
                    quat = pin.Quaternion(M.rotation).coeffs()  # x, y, z, w
                    frame[path].set_property("position", "vector3", M.translation.tolist())
                    frame[path].set_property("quaternion", "quaternion", quat.tolist())

    # A ghost without an estimate is hidden: keys where that changes (a boolean track holds
    # its value), and at the last frame, so that its clip lasts as long as the others.
    for e in legend[1:]:
        seen = present[e.label]
        if seen.all():
            continue
        vis[e.node].set_property("visible", bool(seen[0]))
        for k in sorted({0, n_frames - 1, *(np.flatnonzero(seen[1:] != seen[:-1]) + 1)}):
            with anim.at_frame(vis[e.node], int(k)) as frame:
                frame.set_property("visible", "boolean", bool(seen[k]))

    pts, rad = np.array(points), np.concatenate(radii)
    centre, offset = _camera(pts, rad)
    # meshcat's orbit controls look at the world origin: move the scene (and the
    # floor with it) so that the motion is centred there.
    vis.set_transform(_translation(-centre - shift[0]))
    if follow:
        for k in range(n_frames):
            with anim.at_frame(vis, k) as frame:
                frame.set_property("position", "vector3", (-centre - shift[k]).tolist())
    # meshcat's 20 m grid reaches behind the camera (and software renderers drop
    # lines that cross the camera plane); our own floor lies under the motion.
    vis["/Grid"].set_property("visible", False)
    vertices = _floor(pts, rad, shift, centre, offset)
    vis["floor"].set_object(
        mg.LineSegments(mg.PointsGeometry(vertices.T), mg.LineBasicMaterial(color=0xB4B4B4))
    )
    # meshcat's camera sits in a frame rotated by +90° about x: world (x, y, z) = local (x, -z, y)
    local = [float(offset[0]), float(offset[2]), float(-offset[1])]
    vis["/Cameras/default/rotated/<object>"].set_property("position", local)
    vis.set_animation(anim, play=play, repetitions=_REPEAT)
    return _Scene(legend, rate, notes)


def _floor(points: Vector, radii: Vector, shift: Vector, centre: Vector, offset: Vector) -> Vector:
    """End points (pairs of rows, world frame [m]) of a square floor grid under the truth's motion.

    The floor is the world plane ``z = 0``: where a fixed base is mounted and
    a legged robot stands (an arm reaching below its mounting plane shows
    through the lines).  It covers the motion's footprint with a margin, but
    stops short of the camera so no line passes behind it.  Spacing: 1, 2 or
    5 × 10ᵏ m, about ten squares across.

    Args:
        points: geometry origins of every frame, relative to the followed base ``shift`` [m].
        radii: bounding radius of each point [m].
        shift: followed base position of each frame [m] (zeros for a fixed base).
        centre: centre of the framed motion, relative to ``shift[0]`` [m].
        offset: camera position relative to ``centre`` [m].
    """
    z = 0.0
    lo = np.min(points[:, :2] - radii[:, None], axis=0)
    hi = np.max(points[:, :2] + radii[:, None], axis=0)
    half = max(0.75 * float(np.max(hi - lo)), 0.3)
    reach = float(np.linalg.norm(offset[:2]))
    if reach > 0.3 * float(np.linalg.norm(offset)):  # the camera is off to the side
        half = min(half, 0.85 * reach)
    raw = 2.0 * half / 10.0
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw)
    c = np.round((centre[:2] + shift[0][:2]) / step) * step
    ticks = np.arange(-math.floor(half / step), math.floor(half / step) + 1) * step
    a, b = ticks[0], ticks[-1]
    segments = []
    for u in ticks:
        segments += [[c[0] + u, c[1] + a, z], [c[0] + u, c[1] + b, z]]
        segments += [[c[0] + a, c[1] + u, z], [c[0] + b, c[1] + u, z]]
    return np.array(segments, dtype=float)


def _translation(p: Vector) -> Vector:
    T = np.eye(4)
    T[:3, 3] = p
    return T


# ------------------------------------------------------------------ entry points


def write_html(
    result: Result,
    robot: Robot,
    path: str | Path,
    *,
    fps: float = 30.0,
    observers: Sequence[str] | None = None,
    opacity: float = GHOST_OPACITY,
    title: str | None = None,
    truth_label: str = "truth",
    progress: Progress | None = None,
) -> Path:
    """Write a self-contained HTML playback of ``result`` (opens offline in any browser).

    The page holds meshcat's viewer, the truth, one ghost per observer (legend
    top left), the animation (Open Controls → Animations: play, pause, time
    slider) and, under the 3-D view, the velocity chart (element
    ``#pinobs-chart``: true and estimated velocity of one joint, the error
    norm on a log axis, a cursor at the animation time; dragging on it
    scrubs).  ``page.html#t=1.5`` opens paused at ``t = 1.5 s``.

    The page's size is capped: the keyframes take at most
    :data:`MAX_ANIMATION_BYTES` (8 MB), so a long run gets fewer than ``fps``
    keyframes per second, which the legend and a
    :class:`~pinobs.errors.PinobsWarning` say (:func:`build_scene`).  On top of
    the keyframes: meshcat's viewer (0.9 MB), the meshes (mesh files up to
    4 MB, or decimated triangles) and the chart (at most
    :data:`~pinobs.visualization.chart.MAX_POINTS` samples per curve).

    Args:
        result: the run (``pinobs.simulate`` or ``Result.load``).
        robot: the robot it was run on.
        path: output ``.html`` file (parent folders are created).
        fps: keyframes per second of simulated time [1/s], at most.
        observers: labels to show (default: all).
        opacity: ghost opacity in (0, 1].
        title: legend title (default: robot name and duration).
        truth_label: legend name of ``result.q`` (``"measured"`` for :func:`log_result`).
        progress: called as ``progress(k, n)`` after frame ``k`` of ``n``.

    Returns:
        The path written.
    """
    meshcat = require("meshcat", "meshcat playback")
    path = Path(path)
    window = _RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    scene = _scene(
        vis,
        result,
        robot,
        fps=fps,
        observers=observers,
        opacity=opacity,
        truth_label=truth_label,
        progress=progress,
    )
    legend = scene.legend
    if title is None:
        title = f"pinobs · {robot.name} · {result.t[-1] - result.t[0]:.3g} s"
    ghosts = legend[1:]
    data = chart_data(
        result, robot, [e.label for e in ghosts], [e.colour or "#000000" for e in ghosts]
    )
    overlay = _overlay(title, legend, float(result.t[0]), float(result.t[-1]), scene.notes)
    window.overlay = overlay + chart_html(data)
    page = vis.static_html()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path


def write_html_from_file(
    result_path: str | Path,
    path: str | Path,
    *,
    robot: Robot | None = None,
    fps: float = 30.0,
    progress: Progress | None = None,
) -> Path:
    """Playback of a saved run (``Result.save``): load it, then :func:`write_html`.

    ``robot`` defaults to ``pinobs.load(source)``, ``source`` the registry name or
    file path recorded in the result (``meta["robot_source"]``, else its robot's
    name); pass the robot if it was built otherwise.
    """
    from pinobs.model import load

    result = Result.load(result_path)
    if robot is None:
        meta = result.meta if isinstance(result.meta, dict) else {}
        source = meta.get("robot_source") or result.robot
        robot = load(source, root_joint=meta.get("root_joint"))
    return write_html(result, robot, path, fps=fps, progress=progress)


def log_result(robot: Robot, log: Log, runs: Mapping[str, LogRun]) -> Result:
    """A :class:`Result` for playing back a recorded log and observers run over it.

    The "truth" is the logged configuration (show it with
    ``write_html(..., truth_label="measured")``); its velocity is unknown
    (NaN).  Rows whose time is unreadable or not increasing are left out; an
    unreadable configuration (a dropped sample) stays NaN: the playback holds
    the previous pose there and says so (:func:`build_scene`).

    Args:
        robot: the robot of the log.
        log: from :func:`pinobs.io.read_log`.
        runs: label -> :func:`pinobs.io.estimate_log` output over ``log``.
    """
    t = np.asarray(log.t, dtype=float)
    keep = np.isfinite(t)
    keep &= np.concatenate([[True], t[1:] > np.maximum.accumulate(np.where(keep, t, -np.inf))[:-1]])
    if keep.sum() < 1:
        raise DimensionError("the log has no row with a readable time")
    for name, run in runs.items():
        if run.q.shape != log.q.shape:
            raise DimensionError(
                f"estimates {name!r} have shape {run.q.shape}, the log's q has {log.q.shape}"
            )
    q = np.asarray(log.q, dtype=float)[keep]
    n = int(keep.sum())
    tau = np.zeros((n, robot.nv)) if log.tau is None else np.nan_to_num(log.tau[keep])
    traces = tuple(
        ObserverTrace(
            name=name,
            q=run.q[keep],
            v=run.v[keep],
            update_time=np.full(n, np.nan),
        )
        for name, run in runs.items()
    )
    return Result(
        robot=robot.name,
        t=t[keep],
        q=q,
        v=np.full((n, robot.nv), np.nan),
        tau=tau,
        q_meas=np.asarray(log.q, dtype=float)[keep],
        traces=traces,
        meta={"source": "log"},
    )


@dataclass
class LiveViewer:
    """A playback on a live meshcat server (from :func:`serve`).

    Attributes:
        url: the page to open [http://127.0.0.1:…].
        vis: the ``meshcat.Visualizer`` (send more to it if you like).
        legend: what each colour is.
    """

    url: str
    vis: Any
    legend: list[LegendEntry]

    def close(self) -> None:
        """Close the connection and stop the server if :func:`serve` started it."""
        window = self.vis.window
        socket = getattr(window, "zmq_socket", None)
        if socket is not None:
            socket.close(linger=0)
        proc = getattr(window, "server_proc", None)
        if proc is not None:
            proc.kill()
            proc.wait()
            for pipe in (proc.stdout, proc.stderr):
                if pipe is not None:
                    pipe.close()
            window.server_proc = None

    def __enter__(self) -> LiveViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def serve(
    result: Result,
    robot: Robot,
    *,
    fps: float = 30.0,
    observers: Sequence[str] | None = None,
    opacity: float = GHOST_OPACITY,
    zmq_url: str | None = None,
    open_browser: bool = False,
    progress: Progress | None = None,
    echo: Callable[[str], None] = print,
) -> LiveViewer:
    """Send the playback to a live meshcat server and print its URL and legend.

    ``zmq_url=None`` starts a server (``meshcat-server``, listening on
    127.0.0.1 only) that lives until :meth:`LiveViewer.close` or the end of
    the process; give ``tcp://127.0.0.1:6000`` to use a running one.  The
    legend is printed (meshcat's own page has no overlay).

    Returns:
        The :class:`LiveViewer` (``with serve(...) as viewer: ...`` closes it).
    """
    meshcat = require("meshcat", "live meshcat playback")
    vis = meshcat.Visualizer(zmq_url=zmq_url)
    vis.delete()
    scene = _scene(
        vis, result, robot, fps=fps, observers=observers, opacity=opacity, progress=progress
    )
    legend = scene.legend
    url = str(vis.url())
    echo(f"meshcat playback of {robot.name}: {url}")
    for note in scene.notes:
        echo(f"  {note}")
    for e in legend:
        what = "model colours" if e.colour is None else f"estimate, {e.colour_name}"
        echo(f"  {e.label}: {what}" + (f" ({e.gap_note})" if e.gaps else ""))
    echo("  (Open Controls → Animations: play, pause, time)")
    if open_browser:
        vis.open()
    return LiveViewer(url=url, vis=vis, legend=legend)


def legend_json(entries: Sequence[LegendEntry]) -> str:
    """The legend as JSON (label, colour, colour name, diverged_at), for scripts."""
    return json.dumps(
        [
            {
                "label": e.label,
                "colour": e.colour,
                "colour_name": e.colour_name,
                "diverged_at": e.diverged_at,
            }
            for e in entries
        ]
    )
