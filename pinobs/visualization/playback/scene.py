"""The playback scene: the truth and one ghost per observer loaded into a meshcat
visualizer, animated, framed by the camera, over a floor grid.
"""

from __future__ import annotations

import functools
import math
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
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
from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.simulation import Result
from pinobs.visualization._deps import require
from pinobs.visualization.palette import hex_colour, observer_colours
from pinobs.visualization.playback.geometry import (
    MAX_MESH_FILE_BYTES,
    bounding_radius,
    decimate,
    int_colour,
    mesh_file_bytes,
    model_colours,
    placements,
    triangles,
    visual_model,
)
from pinobs.visualization.playback.legend import LegendEntry
from pinobs.visualization.playback.timeline import (
    budget_note,
    forward_fill,
    frame_indices,
    gap_stretches,
    keyframe_rate,
)

__all__ = ["GHOST_OPACITY", "Progress", "Scene", "build_scene", "make_scene"]


#: Opacity of a ghost (0 invisible, 1 opaque).
GHOST_OPACITY = 0.5

_BACKGROUND = [1.0, 1.0, 1.0]
_CAMERA_FOV_DEG = 75.0  # meshcat's default perspective camera (vertical field of view)
_REPEAT = 1_000_000  # "loop forever": THREE.LoopRepeat needs a finite count
#: What a playback imports (checked first: a missing one is said before any other error).
_NEEDED = (
    "pinocchio.visualize.meshcat_visualizer",
    "meshcat.geometry",
    "meshcat.animation",
    "coal",
)

#: ``progress(k, n)`` is called after frame ``k`` of ``n`` (as in :func:`pinobs.simulate`).
Progress = Callable[[int, int], None]


def _same(value: Any, _go: pin.GeometryObject) -> Any:
    return value


def _safe(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label) or "observer"


@dataclass(frozen=True)
class Scene:
    """What :func:`make_scene` loaded.

    Attributes:
        legend: the truth, then one entry per ghost.
        fps: keyframes per second used [1/s].
        notes: what the page says about its fidelity (a lowered keyframe rate).
    """

    legend: list[LegendEntry]
    fps: float
    notes: list[str]


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

    The keyframes take at most
    :data:`~pinobs.visualization.playback.MAX_ANIMATION_BYTES` of a page (8
    MB): about 132 B per node per frame, a node being one geometry of the
    truth or of a ghost, so a long run (a UR5 with two ghosts: past 100 s)
    gets fewer than ``fps`` keyframes per second, meshcat interpolating
    between them; a :class:`~pinobs.errors.PinobsWarning` gives the rate used.

    Args:
        vis: a ``meshcat.Visualizer`` (live, or recording for
            :func:`~pinobs.visualization.write_html`).
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
    return make_scene(
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


def make_scene(
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
) -> Scene:
    """:func:`build_scene`, also returning the keyframe rate used and the notes on fidelity."""
    for module in _NEEDED:
        require(module, "meshcat playback")
    labels = _checked_labels(result, robot, observers, opacity)
    geom = visual_model(robot, [result.q, *(result.trace(name).q for name in labels)])
    finite = _finite_rows(result)
    estimated = {name: np.all(np.isfinite(result.trace(name).q), axis=1) for name in labels}
    # A floating base (free-flyer, planar root) is followed: the scene moves so
    # that the true base stays in view; a fixed base is framed once.
    follow = bool(robot.joints) and robot.joints[0].kind in ("se3", "se2")
    # animated nodes: each geometry of each copy, a ghost's visibility, the followed scene
    rate = keyframe_rate(result.t, fps, geom.ngeoms * (1 + len(labels)) + len(labels) + follow)
    idx = frame_indices(result.t, rate)
    notes = [] if rate >= fps else [budget_note(result.t, rate, fps)]

    # Scene dressing: white background, no axes, camera framed on the truth.
    vis["/Background"].set_property("top_color", _BACKGROUND)
    vis["/Background"].set_property("bottom_color", _BACKGROUND)
    vis["/Axes"].set_property("visible", False)

    loader = _Loader.start(vis, robot.model, geom, max_triangles)
    truth_nodes, scaled, swatch = loader.truth_copy()
    legend = [
        LegendEntry(
            truth_label,
            None,
            "model colours",
            "truth",
            model_colours=swatch,
            gaps=gap_stretches(result.t, finite),
        )
    ]
    copies = {"truth": truth_nodes}
    # Ghosts: the same shapes, one flat translucent colour each.
    for i, (name, (colour_name, rgb)) in enumerate(
        zip(labels, observer_colours(len(labels), swatch), strict=True)
    ):
        node = f"ghost_{i}_{_safe(name)}"
        copies[name] = loader.copy(node, functools.partial(_same, _ghost_material(rgb, opacity)))
        legend.append(
            LegendEntry(
                name,
                hex_colour(rgb),
                colour_name,
                node,
                result.trace(name).diverged_at,
                gaps=gap_stretches(result.t, estimated[name]),
            )
        )
    _warn(robot.name, notes, legend)

    shown, present = _frames(result, idx, finite, estimated)
    anim = require("meshcat.animation", "meshcat playback").Animation(default_framerate=rate)
    framed = present["truth"] if present["truth"].any() else np.ones(len(idx), dtype=bool)
    points, radii, shift = _keyframes(
        vis, anim, robot.model, geom, shown, copies, scaled, framed, follow, progress
    )
    _visibility(vis, anim, legend[1:], present)
    _view(vis, anim, points, radii, shift, follow)
    vis.set_animation(anim, play=play, repetitions=_REPEAT)
    return Scene(legend, rate, notes)


def _frames(
    result: Result,
    idx: Vector,
    finite: NDArray[np.bool_],
    estimated: Mapping[str, NDArray[np.bool_]],
) -> tuple[dict[str, Vector], dict[str, NDArray[np.bool_]]]:
    """The configuration of the truth and of each estimate (by label) in each frame, and
    whether it is drawn there (its finite rows, ``finite`` and ``estimated``).

    Frame ``k`` shows row ``idx[k]``; a NaN row holds the last finite one (the
    truth's first finite row before any).
    """
    first = result.q[np.argmax(finite)]
    shown = {"truth": forward_fill(result.q, first)[idx]}
    present = {"truth": finite[idx]}
    for name, ok in estimated.items():
        shown[name] = forward_fill(result.trace(name).q, first)[idx]
        present[name] = ok[idx]
    return shown, present


def _checked_labels(
    result: Result, robot: Robot, observers: Sequence[str] | None, opacity: float
) -> list[str]:
    """The observer labels to show, once ``result`` fits ``robot`` and ``opacity`` is valid."""
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
    return labels


def _finite_rows(result: Result) -> NDArray[np.bool_]:
    """Which rows of ``result.q`` are finite; at least one must be."""
    finite = np.all(np.isfinite(result.q), axis=1)
    if not finite.any():
        raise NonFiniteError(
            f"result of robot {result.robot!r}: none of its {len(finite)} configurations "
            "(rows of q) is finite; there is no motion to play back"
        )
    return finite


def _warn(robot_name: str, notes: Sequence[str], legend: Sequence[LegendEntry]) -> None:
    """A warning per note on fidelity and per copy with gaps, attributed to the caller of
    :func:`build_scene`, :func:`~pinobs.visualization.write_html` or
    :func:`~pinobs.visualization.serve`."""
    # (a divergence is reported where it happens; the stretch after it needs no warning)
    told = [e for e in legend if e.gaps and not e.gap_note.startswith("hidden from")]
    for note in [*notes, *(f"{e.label}: {e.gap_note}" for e in told)]:
        # stacklevel: here, make_scene, build_scene / write_html / serve, their caller
        warnings.warn(f"playback of {robot_name}: {note}", PinobsWarning, stacklevel=4)


def _ghost_material(rgb: Sequence[float], opacity: float) -> Any:
    """A ghost's material: one flat colour, ``opacity``.

    Front faces only, no depth writes, pushed slightly away from the camera: the
    truth always shows in full, a ghost shows where it differs from the truth
    and vanishes into it when it has converged; ghosts on each other blend
    instead of z-fighting (mirrored meshes have their winding restored).
    """
    mg = require("meshcat.geometry", "meshcat playback")
    return mg.MeshPhongMaterial(
        color=int_colour(rgb),
        transparent=opacity < 1.0,
        opacity=opacity,
        side=0,
        depthWrite=opacity >= 1.0,
        polygonOffset=True,
        polygonOffsetFactor=1.0,
        polygonOffsetUnits=4.0,
    )


@dataclass(frozen=True)
class _Loader:
    """Loads copies of the robot's shapes into ``vis``.

    Meshes are sent as (decimated) triangle lists, except the truth's mesh
    files when they are small: those go through Pinocchio's visualizer as is
    (textures and per-part colours of Collada files kept).  Primitives
    (boxes, cylinders, ...) are drawn as Pinocchio's visualizer draws them.
    """

    vis: Any
    geom: pin.GeometryModel
    meshes: dict[str, tuple[Vector, NDArray[np.int64]]]  # name -> vertices, triangles
    truth: Any  # pinocchio.visualize.MeshcatVisualizer on ``vis``

    @classmethod
    def start(
        cls, vis: Any, model: pin.Model, geom: pin.GeometryModel, max_triangles: int
    ) -> _Loader:
        """The loader of ``geom``, its meshes decimated to ``max_triangles`` in all."""
        coal = require("coal", "meshcat playback")
        viz_mod = require("pinocchio.visualize.meshcat_visualizer", "meshcat playback")
        meshes = {}
        for go in geom.geometryObjects:
            tri = triangles(go) if not isinstance(go.geometry, coal.ShapeBase) else None
            if tri is not None:
                meshes[go.name] = tri
        total = sum(len(f) for _, f in meshes.values())
        for key, (v, f) in meshes.items():
            share = int(max_triangles * len(f) / total)
            meshes[key] = decimate(v, f, max(200, share) if total > max_triangles else len(f))
        truth = viz_mod.MeshcatVisualizer(model, None, geom)
        truth.initViewer(viewer=vis)
        return cls(vis, geom, meshes, truth)

    def copy(self, node: str, material_of: Callable[[pin.GeometryObject], Any]) -> list[str]:
        """Load a copy under ``node``, each shape in ``material_of(shape)``; its nodes' paths."""
        coal = require("coal", "meshcat playback")
        mg = require("meshcat.geometry", "meshcat playback")
        for go in self.geom.geometryObjects:
            if isinstance(go.geometry, coal.ShapeBase):
                obj = self.truth.loadPrimitive(go)
            elif go.name in self.meshes:
                obj = mg.TriangularMeshGeometry(*self.meshes[go.name])  # meshScale applied
            else:
                obj = None
            if obj is not None:
                self.vis[f"{node}/{go.name}"].set_object(obj, material_of(go))
        return [f"{node}/{go.name}" for go in self.geom.geometryObjects]

    def truth_copy(self) -> tuple[list[str], dict[str, Vector], tuple[str, ...]]:
        """Load the truth: its nodes' paths, the ``meshScale`` its nodes carry (by geometry
        name), and the colours it renders in (most used first)."""
        coal = require("coal", "meshcat playback")
        mg = require("meshcat.geometry", "meshcat playback")
        viz_mod = require("pinocchio.visualize.meshcat_visualizer", "meshcat playback")
        geom = self.geom
        as_is = mesh_file_bytes(geom) <= MAX_MESH_FILE_BYTES
        scaled: dict[str, Vector] = {}
        if as_is:
            # The truth, as the model describes it, through Pinocchio's visualizer.
            self.truth.loadViewerModel(rootNodeName="truth")
            nodes = [f"truth/visuals/{go.name}" for go in geom.geometryObjects]
            # mesh-file objects drawn by Pinocchio carry meshScale in their node's scale
            scaled = {
                go.name: np.asarray(go.meshScale, dtype=float)
                for go in geom.geometryObjects
                if viz_mod.hasMeshFileInfo(go) and not isinstance(go.geometry, coal.ShapeBase)
            }
        else:
            nodes = self.copy(
                "truth", lambda go: mg.MeshPhongMaterial(color=int_colour(go.meshColor[:3]))
            )
        return nodes, scaled, model_colours(geom, collada_materials=as_is)


def _keyframes(
    vis: Any,
    anim: Any,
    model: pin.Model,
    geom: pin.GeometryModel,
    shown: Mapping[str, Vector],
    copies: Mapping[str, Sequence[str]],
    scaled: Mapping[str, Vector],
    framed: NDArray[np.bool_],
    follow: bool,
    progress: Progress | None,
) -> tuple[Vector, Vector, Vector]:
    """Key every copy's placements at each frame (and pose it at the first).

    Args:
        shown: label -> configuration of each frame (``"truth"`` first).
        copies: label -> the paths of its nodes.
        scaled: the truth's ``meshScale`` by geometry name, where its node carries it.
        framed: the frames the camera frames (the truth's finite rows).
        follow: whether the scene follows the truth's floating base.

    Returns:
        The truth's geometry origins in every framed frame, relative to the followed base
        [m], their bounding radii [m], and the followed base's position in each frame [m]
        (zeros for a fixed base).
    """
    data = model.createData()
    gdata = pin.GeometryData(geom)
    points: list[Vector] = []
    radii_one = np.array([bounding_radius(go) for go in geom.geometryObjects])
    radii: list[Vector] = []
    n_frames = len(framed)
    shift = np.zeros((n_frames, 3))
    total = n_frames * len(shown)
    done = 0
    for who, qs in shown.items():
        for k in range(n_frames):
            done += 1
            if progress is not None:
                progress(done, total)
            oMg = placements(model, data, geom, gdata, qs[k])
            if who == "truth":
                if follow:
                    shift[k] = data.oMi[1].translation
                if framed[k]:  # the camera frames finite rows only
                    points.extend(M.translation - shift[k] for M in oMg)
                    radii.append(radii_one)
            if k == 0:  # a static pose too (with the mesh scale), for viewers without animation
                _static_pose(vis, geom, copies[who], oMg, scaled if who == "truth" else {})
            with anim.at_frame(vis, k) as frame:
                for path, M in zip(copies[who], oMg, strict=True):
                    quat = pin.Quaternion(M.rotation).coeffs()  # x, y, z, w
                    frame[path].set_property("position", "vector3", M.translation.tolist())
                    frame[path].set_property("quaternion", "quaternion", quat.tolist())
    return np.array(points), np.concatenate(radii), shift


def _static_pose(
    vis: Any,
    geom: pin.GeometryModel,
    paths: Sequence[str],
    oMg: Sequence[pin.SE3],
    scaled: Mapping[str, Vector],
) -> None:
    """Pose the nodes ``paths`` of one copy at the placements ``oMg``, a geometry named in
    ``scaled`` with its mesh scale."""
    for go, path, M in zip(geom.geometryObjects, paths, oMg, strict=True):
        T = M.homogeneous
        if go.name in scaled:
            T = T @ np.diag([*scaled[go.name], 1.0])
        vis[path].set_transform(T)


def _visibility(
    vis: Any, anim: Any, ghosts: Sequence[LegendEntry], present: Mapping[str, NDArray[np.bool_]]
) -> None:
    """A ghost without an estimate is hidden: keys where that changes (a boolean track holds
    its value), and at the last frame, so that its clip lasts as long as the others."""
    for e in ghosts:
        seen = present[e.label]
        if seen.all():
            continue
        vis[e.node].set_property("visible", bool(seen[0]))
        for k in sorted({0, len(seen) - 1, *(np.flatnonzero(seen[1:] != seen[:-1]) + 1)}):
            with anim.at_frame(vis[e.node], int(k)) as frame:
                frame.set_property("visible", "boolean", bool(seen[k]))


def _view(vis: Any, anim: Any, points: Vector, radii: Vector, shift: Vector, follow: bool) -> None:
    """Frame the truth's motion (``points``, ``radii`` and ``shift`` as from :func:`_keyframes`):
    the scene centred, the camera placed, a floor under it."""
    mg = require("meshcat.geometry", "meshcat playback")
    centre, offset = _camera(points, radii)
    # meshcat's orbit controls look at the world origin: move the scene (and the
    # floor with it) so that the motion is centred there.
    vis.set_transform(_translation(-centre - shift[0]))
    if follow:
        for k in range(len(shift)):
            with anim.at_frame(vis, k) as frame:
                frame.set_property("position", "vector3", (-centre - shift[k]).tolist())
    # meshcat's 20 m grid reaches behind the camera (and software renderers drop
    # lines that cross the camera plane); our own floor lies under the motion.
    vis["/Grid"].set_property("visible", False)
    vertices = _floor(points, radii, shift, centre, offset)
    vis["floor"].set_object(
        mg.LineSegments(mg.PointsGeometry(vertices.T), mg.LineBasicMaterial(color=0xB4B4B4))
    )
    # meshcat's camera sits in a frame rotated by +90° about x: world (x, y, z) = local (x, -z, y)
    local = [float(offset[0]), float(offset[2]), float(-offset[1])]
    vis["/Cameras/default/rotated/<object>"].set_property("position", local)


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
