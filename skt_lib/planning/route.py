"""The threading route of a supporting item, from its mesh alone: where a ring hung on an arm
must pass to get off it — back along the arm from the hang, over its tip and on past it.

The arm is the mesh's own skeleton (:func:`skt_lib.geometry.centreline.find_arms`, so imported
hooks get a route too, not only ``mesh_gen``'s strokes): the arm whose centreline passes
nearest the hanging keypoint. The keypoint keeps its place relative to the rod: its offset from
the nearest centreline point at the hang is carried along the centreline by the smallest
rotation between consecutive tangents (parallel transport, as the SKT frames carry the roll),
so where the arm turns up into a tip the keypoint turns with it, on the side of the rod the
ring holds it by. Past the tip the route runs straight on along the tip's direction.

The planner draws a share of its tree samples near this route (``route_bias``): a tree grown
from the hang then follows the arm over an upturned tip instead of searching the whole box
for the one narrow way out.
"""

from collections.abc import Callable

import numpy as np

from skt_lib.errors import MeshError
from skt_lib.geometry.centreline import find_arms
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.skt import minimal_rotation

#: Spacing of route points (m).
ROUTE_STEP_M = 0.001


def arm_route(mesh: Mesh, hang: np.ndarray, beyond_m: float, arms=None) -> np.ndarray:
    """Keypoint positions ``(K, 3)`` (support frame), ``ROUTE_STEP_M`` apart, from the hanging
    keypoint ``hang (3,)`` along the arm nearest it to its tip and ``beyond_m`` on past it
    (module docstring). ``arms``: :func:`find_arms` of ``mesh`` when already known. Raises
    :class:`~skt_lib.errors.MeshError` when the mesh has no arm."""
    hang = np.asarray(hang, float)
    arms = find_arms(mesh) if arms is None else arms
    arm = min(arms, key=lambda a: float(np.linalg.norm(a.dense - hang, axis=1).min()))
    i = int(np.argmin(np.linalg.norm(arm.dense - hang, axis=1)))
    centre = _even(arm.dense[i:])
    if len(centre) < 2:  # the hang is at the tip: the route is the way on past it
        centre = np.vstack([arm.dense[i], arm.dense[i] + ROUTE_STEP_M * _tip_direction(arm.dense)])
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    offset = [hang - centre[0]]
    for a, b in zip(tangent[:-1], tangent[1:]):
        side = np.cross(a, [0.0, 0.0, 1.0])
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.array([0.0, 1.0, 0.0])
        offset.append(minimal_rotation(a, b, side) @ offset[-1])
    route = centre + np.asarray(offset)
    n_on = int(np.ceil(beyond_m / ROUTE_STEP_M))
    on = route[-1] + np.outer(np.arange(1, n_on + 1) * ROUTE_STEP_M, tangent[-1])
    return np.vstack([route, on])


def _even(points: np.ndarray) -> np.ndarray:
    """``points`` resampled to :data:`ROUTE_STEP_M` by arc length (ends kept)."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if s[-1] < ROUTE_STEP_M:
        return points[:1]
    t = np.linspace(0.0, s[-1], int(np.ceil(s[-1] / ROUTE_STEP_M)) + 1)
    return np.stack([np.interp(t, s, points[:, k]) for k in range(3)], axis=1)


def _tip_direction(dense: np.ndarray) -> np.ndarray:
    d = dense[-1] - dense[max(0, len(dense) - 6)]
    if np.linalg.norm(d) < 1e-9:
        raise MeshError("the hanging arm has no direction at its tip")
    return d / np.linalg.norm(d)


def route_sampler(route: np.ndarray, spread_m: float) -> Callable[[np.random.Generator], np.ndarray]:
    """``sample(rng) -> (3,)``: a point of ``route`` chosen uniformly, moved by isotropic
    Gaussian noise of ``spread_m`` per axis."""
    route = np.asarray(route, float)

    def sample(rng: np.random.Generator) -> np.ndarray:
        return route[rng.integers(len(route))] + rng.normal(0.0, spread_m, 3)

    return sample
