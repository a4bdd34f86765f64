"""The threading planner's settings (:class:`ThreadSettings`, keyword-only: thirteen numbers
are too many to pass by position) and its one failure (:class:`ThreadingFailed`, whose
``reason`` names why no SKT came out). Both planners of :mod:`skt_lib.planning.threading`
and every room they are built from (:mod:`~skt_lib.planning.checker`,
:mod:`~skt_lib.planning.tree`, :mod:`~skt_lib.planning.release`,
:mod:`~skt_lib.planning.smoothing`) read them, so they live below all of these."""

from dataclasses import dataclass

from skt_lib.errors import ItemFailure


class ThreadingFailed(ItemFailure):
    reason = "no_path"


@dataclass(frozen=True, kw_only=True)
class ThreadSettings:
    step_m: float  # tree edge length
    max_turn_deg: float  # largest change of motion direction between consecutive edges
    lead_in_m: float  # straight final approach along the hanging keypoint's x axis
    max_release_offset_m: float  # ξ_0 may be this far from the hang (lifted / back)
    check_step_m: float  # largest motion of any probe point between checked poses
    probe_radius_m: float  # farthest probe point from the keypoint
    goal_bias: float  # share of tree samples drawn in the start region
    surface_bias: float  # share of tree samples drawn near the support's surface
    max_checks: int  # budget, in pose checks
    shortcut_steps: int  # shortcut attempts on the found path
    T: int  # waypoints the SKT is executed with (resampled)
    plane_bias: float = 0.0  # share of tree samples moved onto the threading plane
    route_bias: float = 0.0  # share of tree samples drawn near the arm's threading route
