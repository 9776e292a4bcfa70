"""The robot's shapes in a playback: visual geometry or a stick figure, meshes, colours.

The truth is drawn from the model's visual geometry (its mesh files as they are
when they are small, :data:`MAX_MESH_FILE_BYTES`), a ghost from the same shapes
as triangle lists, decimated to a budget (:func:`decimate`).  A robot without
visual geometry gets a stick figure (:func:`stick_figure`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from pinobs.model import Robot
from pinobs.model.robot import Vector
from pinobs.visualization._deps import require
from pinobs.visualization.axes import slide_axis
from pinobs.visualization.palette import hex_colour

__all__ = [
    "MAX_MESH_FILE_BYTES",
    "bounding_radius",
    "decimate",
    "int_colour",
    "mesh_file_bytes",
    "model_colours",
    "placements",
    "stick_figure",
    "triangles",
    "truth_colours",
    "visual_model",
]


#: Mesh files (Collada, STL, OBJ) up to this total size are sent as they are
#: for the truth; above it the truth gets the same decimated triangles as the ghosts.
MAX_MESH_FILE_BYTES = 4_000_000


def int_colour(rgb: Sequence[float]) -> int:
    """``0xRRGGBB`` of an RGB triple in [0, 1] (meshcat's material colour)."""
    r, g, b = (round(255 * float(c)) for c in rgb[:3])
    return r * 65536 + g * 256 + b


def model_colours(
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
    geom = visual_model(robot)
    return model_colours(geom, collada_materials=mesh_file_bytes(geom) <= MAX_MESH_FILE_BYTES)


def stick_figure(
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


def visual_model(robot: Robot, configurations: Sequence[Vector] = ()) -> pin.GeometryModel:
    """The robot's visual geometry, or a stick figure whose prismatic rails span the
    ``configurations`` (rows of ``q``) played back."""
    vm = robot.visual_model
    if vm is None or vm.ngeoms == 0:
        return stick_figure(robot.model, _travel(robot, configurations) if configurations else None)
    return vm


def decimate(
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


def triangles(go: pin.GeometryObject) -> tuple[Vector, NDArray[np.int64]] | None:
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


def mesh_file_bytes(geom: pin.GeometryModel) -> int:
    """Total size [B] of the mesh files (Collada, STL, OBJ) ``geom`` draws from."""
    total = 0
    for go in geom.geometryObjects:
        p = Path(go.meshPath) if go.meshPath else None
        if p is not None and p.suffix.lower() in (".dae", ".stl", ".obj") and p.is_file():
            total += p.stat().st_size
    return total


def bounding_radius(go: pin.GeometryObject) -> float:
    """Radius [m] of a sphere about the geometry's origin holding it (0.05 if unknown)."""
    geometry = go.geometry
    try:
        geometry.computeLocalAABB()
        r = float(geometry.aabb_radius) + float(np.linalg.norm(geometry.aabb_center))
    except (AttributeError, RuntimeError):
        return 0.05
    return r * float(np.max(np.abs(go.meshScale))) if np.isfinite(r) else 0.05


def placements(
    model: pin.Model, data: pin.Data, geom: pin.GeometryModel, gdata: pin.GeometryData, q: Vector
) -> list[pin.SE3]:
    """World placement of each geometry of ``geom`` at configuration ``q`` (copies)."""
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, geom, gdata)
    return [gdata.oMg[i].copy() for i in range(geom.ngeoms)]
