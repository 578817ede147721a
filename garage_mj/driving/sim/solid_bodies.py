"""The solid bodies of a compiled drive scene as floor outlines: what SPEC 9 judges a park test against.

:func:`solid_bodies` reads them off the MuJoCo model and data the car drives in, so it sees each body where
it actually stands (a parked car drawn with an offset or a heading jitter, a pillar, a wall, an obstacle
block), never a stall outline: every geom of a collidable class (:data:`~garage_mj.scene.semantics.COLLIDABLE`)
that is in place (it collides: a parked car of an empty stall does not), is not the car's own, and reaches
into the height band of the car's own collision geoms (a ceiling above the car is no obstacle to it).
Each box geom gives its footprint (the box turned only about the vertical: its rectangle; turned otherwise:
the bounding rectangle of its corners), a mesh geom the smallest rectangle holding its vertices; any other geom
type its bounding square (``geom_rbound``), a bound that never makes a body look farther than it is.
"""

from __future__ import annotations

import mujoco
import numpy as np

from garage_mj.scene.body_outlines import BodyOutlines
from garage_mj.scene.semantics import COLLIDABLE, Semantic

_VERTICAL = 1e-6  # a box whose z axis is this close to vertical is turned about the vertical only


def _extent(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[np.ndarray, float, float]:
    """Geom ``g``'s floor outline (4, 2) [m] and its height band (z low, z high)."""
    pos, rot = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
    if int(model.geom_type[g]) == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = int(model.geom_dataid[g])
        vert = pos + model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]] @ rot.T
        return _smallest_rectangle(vert[:, :2]), float(vert[:, 2].min()), float(vert[:, 2].max())
    if int(model.geom_type[g]) == mujoco.mjtGeom.mjGEOM_BOX:
        half = model.geom_size[g]
        signs = np.array([[1, 1, 1], [-1, 1, 1], [-1, -1, 1], [1, -1, 1]], dtype=float)
        top = pos + (signs * half) @ rot.T  # four corners of one face, in order round it
        zr = float(np.abs(rot[2]) @ half)
        if abs(rot[2, 2]) >= 1 - _VERTICAL:
            corners = top[:, :2]
        else:  # turned about a horizontal axis too: the bounding rectangle of all eight corners
            every = pos + (np.vstack([signs, signs * [1, 1, -1]]) * half) @ rot.T
            (x0, y0), (x1, y1) = every[:, :2].min(axis=0), every[:, :2].max(axis=0)
            corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        return corners, float(pos[2]) - zr, float(pos[2]) + zr
    r = float(model.geom_rbound[g])
    x, y, z = (float(v) for v in pos)
    return np.array([[x - r, y - r], [x + r, y - r], [x + r, y + r], [x - r, y + r]]), z - r, z + r


def _smallest_rectangle(points: np.ndarray) -> np.ndarray:
    """(4, 2) the smallest-area rectangle holding ``points`` (N, 2), in order round it: one side lies along a side of
    their convex hull, so the directions between any two points hold the best one (a mesh has few vertices)."""
    d = (points[None] - points[:, None]).reshape(-1, 2)
    d = d[np.hypot(d[:, 0], d[:, 1]) > 1e-9]
    u = d / np.hypot(d[:, 0], d[:, 1])[:, None]  # (D, 2) candidate axes
    a = points @ u.T  # (N, D) along each axis
    b = points @ np.stack([-u[:, 1], u[:, 0]], axis=1).T  # across
    k = int(np.argmin(np.ptp(a, axis=0) * np.ptp(b, axis=0)))
    ux, vx = u[k], np.array([-u[k, 1], u[k, 0]])
    (a0, a1), (b0, b1) = (a[:, k].min(), a[:, k].max()), (b[:, k].min(), b[:, k].max())
    return np.array([ux * s + vx * t for s, t in ((a0, b0), (a1, b0), (a1, b1), (a0, b1))])


def solid_bodies(model: mujoco.MjModel, data: mujoco.MjData, own: np.ndarray, classes: np.ndarray) -> BodyOutlines:
    """The floor outlines of the solid bodies around the car (module docstring).

    ``own``: (ngeom,) bool, the car's own geoms; ``classes``: (ngeom,) the class of each geom
    (:func:`~garage_mj.scene.semantics.geom_classes`). ``data`` must hold the current kinematics (after a reset
    or a step).
    """
    solid = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    mine = np.flatnonzero(own & solid)
    if len(mine):
        bands = [_extent(model, data, int(g))[1:] for g in mine]
        low, high = min(b[0] for b in bands), max(b[1] for b in bands)
    else:
        low, high = -np.inf, np.inf
    keep = np.flatnonzero(np.isin(classes, [int(c) for c in COLLIDABLE]) & solid & ~own)
    corners, names, kinds = [], [], []
    for g in keep:
        outline, z0, z1 = _extent(model, data, int(g))
        if z1 <= low or z0 >= high:
            continue
        corners.append(outline)
        kinds.append(Semantic(int(classes[g])).name.lower())
        names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(g)) or f"geom_{int(g)}")
    return BodyOutlines(np.array(corners, dtype=float).reshape(-1, 4, 2), tuple(kinds), tuple(names))


__all__ = ["solid_bodies"]
