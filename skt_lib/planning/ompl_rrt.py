"""OMPL RRT-Connect in SE(3) for one rigid object, deterministic under a seed.

OMPL's random generator can be seeded only before its first use in a process, so callers
plan inside :func:`skt_lib.parallel.run_forked` children (see ``skts.py``). Planning stops
after a fixed number of validity checks, never after a wall-clock time, so the result does
not depend on machine speed. Simplification is step-bounded for the same reason.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou
from scipy.spatial.transform import Rotation

from skt_lib.errors import ItemFailure
from skt_lib.geometry.se3 import matrix_to_quat, quat_to_matrix

ou.setLogLevel(ou.LOG_ERROR)


class PlanningFailed(ItemFailure):
    reason = "no_path"


@dataclass(frozen=True)
class PlanSettings:
    range_m: float  # RRT-Connect extension length (SE(3) metric, see below)
    check_step_m: float  # motion validity checked every this much
    max_checks: int  # planning budget in validity checks
    simplify_steps: int  # shortcut / vertex-reduction attempts
    dense_step_m: float  # spacing of the returned states
    rotation_weight_m: float  # object radius, m: bounds the motion of its points (see plan)


def seed_ompl(seed: int) -> None:
    """Seed OMPL; only effective before OMPL's first random number in this process."""
    ou.RNG.setSeed(int(seed))


def _to_state(space, t: np.ndarray):
    s = space.allocState()
    s.setXYZ(*map(float, t[:3, 3]))
    q = matrix_to_quat(t[:3, :3])
    r = s.rotation()
    r.x, r.y, r.z, r.w = map(float, q)
    return s


def _to_matrix(s) -> np.ndarray:
    r = s.rotation()
    t = np.eye(4)
    t[:3, :3] = quat_to_matrix([r.x, r.y, r.z, r.w])
    t[:3, 3] = (s.getX(), s.getY(), s.getZ())
    return t


def plan(start: np.ndarray, goal: np.ndarray, collides: Callable[[tuple, tuple], bool],
         lower: np.ndarray, upper: np.ndarray, p: PlanSettings) -> tuple[np.ndarray, int]:
    """Collision-free object poses ``(N, 4, 4)`` from ``start`` to ``goal`` (both kept
    exactly), consecutive states at most ``dense_step_m`` apart in the SE(3) metric.

    OMPL's SO(3) distance is half the rotation angle, so with the rotation subspace weighted
    ``2 × rotation_weight_m`` the metric (translation + weighted half-angle) bounds how far any
    point within that radius of the object origin moves. Returns (poses, validity checks
    used); raises :class:`PlanningFailed`."""
    space = ob.SE3StateSpace()
    bounds = ob.RealVectorBounds(3)
    for k in range(3):
        bounds.setLow(k, float(lower[k]))
        bounds.setHigh(k, float(upper[k]))
    space.setBounds(bounds)
    space.setSubspaceWeight(1, 2.0 * float(p.rotation_weight_m))
    si = ob.SpaceInformation(space)
    checks = [0]

    def valid(s) -> bool:
        checks[0] += 1
        r = s.rotation()
        return space.satisfiesBounds(s) and not collides((s.getX(), s.getY(), s.getZ()),
                                                         (r.x, r.y, r.z, r.w))

    si.setStateValidityChecker(valid)
    si.setStateValidityCheckingResolution(p.check_step_m / space.getMaximumExtent())
    si.setup()
    s0, s1 = _to_state(space, start), _to_state(space, goal)
    if not si.isValid(s0):
        raise PlanningFailed("start pose collides or is out of bounds", "start_in_collision")
    if not si.isValid(s1):
        raise PlanningFailed("goal pose collides or is out of bounds", "goal_in_collision")
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(s0, s1)
    planner = og.RRTConnect(si)
    planner.setRange(p.range_m)
    planner.setProblemDefinition(pdef)
    planner.setup()
    planner.solve(ob.PlannerTerminationCondition(lambda: checks[0] >= p.max_checks))
    if not pdef.hasExactSolution():
        raise PlanningFailed(f"no path within {p.max_checks} validity checks", "no_path")
    path = pdef.getSolutionPath()
    simplifier = og.PathSimplifier(si)
    simplifier.reduceVertices(path, p.simplify_steps)
    simplifier.partialShortcutPath(path, p.simplify_steps)
    simplifier.smoothBSpline(path, 3)
    if not path.check():
        raise PlanningFailed("simplified path is invalid", "simplify_invalid")
    corners = np.stack([_to_matrix(path.getState(i)) for i in range(path.getStateCount())])
    corners[0], corners[-1] = start, goal
    return densify(corners, p.rotation_weight_m, p.dense_step_m), checks[0]


def densify(poses: np.ndarray, radius: float, step: float) -> np.ndarray:
    """Insert poses (linear translation, slerp rotation) so that no point within ``radius``
    of the object origin moves more than ``step`` between consecutive poses: a segment
    with translation ``d`` and rotation angle ``θ`` gets ``ceil((d + radius·θ) / step)``
    sub-steps. Keeps every input pose."""
    out = [poses[:1]]
    for a, b in zip(poses[:-1], poses[1:]):
        rel = Rotation.from_matrix(a[:3, :3].T @ b[:3, :3])
        bound = np.linalg.norm(b[:3, 3] - a[:3, 3]) + radius * rel.magnitude()
        n = max(1, int(np.ceil(bound / step)))
        u = np.arange(1, n + 1) / n
        seg = np.tile(np.eye(4), (n, 1, 1))
        seg[:, :3, :3] = a[:3, :3] @ Rotation.from_rotvec(np.outer(u, rel.as_rotvec())).as_matrix()
        seg[:, :3, 3] = a[:3, 3] + np.outer(u, b[:3, 3] - a[:3, 3])
        seg[-1] = b
        out.append(seg)
    return np.concatenate(out)
