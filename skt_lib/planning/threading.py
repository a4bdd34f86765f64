"""Threading planner: SKTs that are collision-free *as executed*. The two planners live here:

- :func:`plan_threading_many` — **the fast default** (``rrt_skts.planner: one_tree``): every
  SKT of a support read out of one tree grown from the hang;
- :func:`plan_threading` — **the reference** (``rrt_skts.planner: per_skt``): a fresh tree
  per SKT. It is kept as it was and runnable, so that ``make bench``
  (:mod:`skt_lib.planning.bench`) can time the fast planner against it on the same supports.

They are built from rooms of their own, which this module only puts together:

- :mod:`skt_lib.planning.thread_settings` — :class:`ThreadSettings` (the knobs, keyword-only)
  and :class:`ThreadingFailed` (also importable from here);
- :mod:`skt_lib.planning.frames` — SKT frames in execution order, transport, the turn limit,
  quaternions;
- :mod:`skt_lib.planning.checker` — :class:`~skt_lib.planning.checker.Checker`, every pose
  checked as executed and counted against the budget;
- :mod:`skt_lib.planning.release` — the release ξ_0 near the hang and its straight lead-in;
- :mod:`skt_lib.planning.tree` — the backward tree and its sampler (threading plane);
- :mod:`skt_lib.planning.smoothing` — a leaf's path joined to its start, shortcut, resampled
  to ``T`` and checked once more.

How it works, in full:

An SKT is executed with its rotation-minimizing frames (:func:`skt_lib.geometry.skt.skt_frames`:
x = direction of motion, the roll carried along the path from the hanging orientation), so the
object's orientation is tied to the way it moves — it is threaded along the path like a ring
along a wire, over an upturned tip and down along it as well as straight in. This planner
searches keypoint positions only, with every pose checked at exactly the frame execution will
give it:

- a tree grows backward from the hang ξ_0 with edges of ``step_m``; the first ``lead_in_m``
  is a straight line along the arrival direction — the hanging keypoint's x axis or, where
  that is blocked (an upright in front of the hang), the nearest clear direction turned from
  it — whose rule frame anchors the SKT frames: the hanging orientation the object ends at;
- each node carries the frame its parent's is transported to along the edge (the minimal
  rotation between consecutive motion directions), so frames are defined while the tree
  grows, for any direction of motion — vertical included (no pitch limit); an edge may turn
  the motion by at most ``max_turn_deg`` from the next edge;
- the release ξ_0 is the hanging keypoint, or where the probe does not fit there (a ring
  tilted along an angled peg meets the wall plate at the hang), a point at most
  ``max_release_offset_m`` (≤ 4 mm) from it, lifted above it and/or moved back along the
  arrival (the object drops or slides the rest of the way in); nothing is set back in front
  of the hang beyond that, so every SKT this planner returns ends at the hang;
- every pose is checked with the *probe*: the reference object (and, when asked, every
  training object) at its own keypoint frame, against the support and the wall. The frame at
  a waypoint depends on the motion arriving at it, so adding a child re-checks its parent's
  edge with the orientation that child gives it;
- samples are drawn in the start region (``goal_bias``), near the support's surface
  (``surface_bias``, from the caller's ``sample_near``: points offset from the mesh along its
  normals, so the tree follows hooks and tips of any shape, imported meshes included), near
  the hanging arm's threading route (``route_bias``, from the caller's ``sample_route``:
  :mod:`skt_lib.planning.route`), or uniformly in the bounds; a ``plane_bias`` share of them,
  of every kind but the route's, is moved onto the *threading plane*
  (:func:`~skt_lib.planning.tree.threading_plane`: the vertical plane through the hang that
  holds the arrival direction), where a ring goes over a tip and down it without turning sideways.
  A path that leaves that plane to pass a tip beside it turns the object about the vertical
  and, through the transported frames, rolls it: its start orientation ends up far from the
  hanging one (up to 180°), which the arm cannot follow and a learned template cannot average;
- when a node reaches the start region, the path is joined straight to the canonical
  start (when given: the region's centre) from the first of its vertices where that stretch
  keeps the turn limit and is clear, so SKTs of one support start at one point and differ only where the support makes
  them; then it is shortcut (random, seeded; a shortcut rolls the frames of everything
  before it, so every segment whose frames change is re-checked), resampled to the evaluated
  ``T`` waypoints, and checked once more as executed at that resolution; a path that fails
  there is dropped and a fresh tree grows (the same budget). What passes is what
  ``sim_eval`` executes;
- :func:`plan_threading_many` reads many SKTs out of **one** tree (every SKT of a support
  ends at the same hang, and the threading from it is the costly part): each SKT takes a
  leaf of its own and its own start, and is joined, shortcut and checked as above.

Deterministic: the caller's generator drives every sample; the budget is counted in checks.
"""

from collections.abc import Callable

import numpy as np

from skt_lib.planning.checker import Checker
from skt_lib.planning.frames import unit
from skt_lib.planning.release import releases
from skt_lib.planning.smoothing import read_out
from skt_lib.planning.thread_settings import ThreadingFailed, ThreadSettings
from skt_lib.planning.tree import STUCK_CHECKS, Sampler, Tree, threading_plane

__all__ = ["ThreadSettings", "ThreadingFailed", "plan_threading", "plan_threading_many"]


def plan_threading(goal: np.ndarray, in_start: Callable[[np.ndarray], bool],
                   sample_start: Callable[[np.random.Generator], np.ndarray],
                   lower: np.ndarray, upper: np.ndarray, collides: Callable[[np.ndarray], bool],
                   s: ThreadSettings, rng: np.random.Generator,
                   start_point: np.ndarray | None = None,
                   sample_near: Callable[[np.random.Generator], np.ndarray] | None = None,
                   sample_route: Callable[[np.random.Generator], np.ndarray] | None = None
                   ) -> tuple[np.ndarray, int]:
    """The reference planner (``rrt_skts.planner: per_skt``; kept runnable for ``make bench``,
    the default is :func:`plan_threading_many`): one SKT from a fresh tree.

    Keypoint positions ``(N, 3)``, ξ_0 (within ``max_release_offset_m`` of the hang) first,
    vertices at most ``step_m`` apart, whose execution (SKT frames) is clear for
    ``collides``; and the checks used.

    ``goal``: the hanging keypoint frame (4×4, support frame; its x axis is the threading
    direction). ``in_start(p)``: whether a keypoint position may start the SKT;
    ``sample_start(rng)``: a position in that region. ``collides(position, quat)``: the probe
    at a keypoint pose touches the support or wall. ``start_point``: the canonical start the
    path is extended to when it can be; ``sample_near(rng)``: a position near the support's
    surface (drawn with ``surface_bias``); ``sample_route(rng)``: a position near the arm's
    threading route (:mod:`skt_lib.planning.route`, drawn with ``route_bias``, never moved
    onto the threading plane). Raises :class:`ThreadingFailed`."""
    check = Checker(collides, s)
    sampler = Sampler(sample_start, sample_near, lower, upper, s,
                      threading_plane(goal) if s.plane_bias > 0 else None, sample_route)
    n_rejected = 0
    for lead, a0, r0 in releases(goal[:3, 3], unit(goal[:3, 0]), check, s):
        while True:  # fresh trees from this release until one survives resampling (one budget)
            n_before = check.n
            try:
                tree = Tree(lead, a0, r0, lower, upper, check, s)
                leaf = tree.grow(in_start, sampler, rng, s.max_checks)
            except ThreadingFailed:
                if n_rejected:
                    raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to "
                                          f"T = {s.T}; budget spent", "resample_collision") from None
                raise
            if leaf is None:
                break  # stuck: next release
            dense = read_out(tree, leaf, start_point, check, s, rng)
            if dense is not None:
                return dense, check.n
            n_rejected += 1
            if check.n == n_before:  # nothing new can come from this release
                break
    if n_rejected:
        raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to T = {s.T}",
                              "resample_collision")
    raise ThreadingFailed("the tree could not leave any clear release", "stuck")



#: Leaves of one tree of :func:`plan_threading_many` that may collide once resampled, in a
#: row, before a fresh tree grows (each further leaf costs only the tree's growth from where
#: it stands; a fresh tree pays the threading again).
MISSES_PER_TREE = 4
#: Leaves an SKT of :func:`plan_threading_many` joins to its own start before it joins the
#: next ones to SKT 0's (the region's centre): a start whose joined paths keep colliding once
#: resampled would otherwise spend the SKT's whole budget (measured on support_00001, 50
#: SKTs: 3 of them took 73k–150k checks, 30 s of the support's 31 s).
START_TRIES = 2
#: A further leaf of :func:`plan_threading_many` must come within this share of
#: ``max_checks`` (the first leaf has the whole budget: it threads the hang).
LEAF_BUDGET_SHARE = 0.1


def plan_threading_many(goal: np.ndarray, starts: np.ndarray,
                        in_start: Callable[[np.ndarray], bool],
                        sample_start: Callable[[np.random.Generator], np.ndarray],
                        lower: np.ndarray, upper: np.ndarray, collides: Callable,
                        s: ThreadSettings, rng: np.random.Generator,
                        sample_near: Callable | None = None,
                        sample_route: Callable | None = None):
    """The fast default planner (``rrt_skts.planner: one_tree``): many SKTs from one tree.

    ``len(starts)`` SKTs from **one** tree (the arguments as :func:`plan_threading`'s),
    yielded one at a time as ``(dense SKT ξ_0 first | None, failure reason | None, pose checks
    used so far)``, SKT ``i`` joined to ``starts[i]``.

    Every SKT of a support ends at the same hang, and the costly part of a search is the
    threading from it — over an upturned tip, through a curl. So one tree is grown backward
    from the first release it can leave (as :func:`plan_threading`), and each SKT is read out
    of it: SKT ``i`` takes a leaf of its own (a node in the start region; leaves are never
    extended, so each is a distinct path), is joined to its own start ``starts[i]``, shortcut
    with the shared generator, resampled and checked as executed — every check of the
    per-SKT planner, none shared but the tree's. A further leaf is grown from the tree as it
    stands (within :data:`LEAF_BUDGET_SHARE` of the budget). A leaf whose resampled
    execution collides is replaced; after :data:`MISSES_PER_TREE` such leaves in a row (or a
    tree that gives no further leaf) the tree's trunk is the trouble (a curl whose
    resampling cuts a corner), and a fresh tree grows from the same release, as the per-SKT
    planner would. After :data:`START_TRIES` such leaves an SKT is joined to ``starts[0]``
    instead of its own start. Each SKT has the per-SKT planner's budget, ``max_checks`` pose checks
    (SKT 0's counted from the start, the tree included); spent, it fails as ``no_path`` or,
    where leaves were read out but collided once resampled, ``resample_collision``.

    With the same generator state and ``starts[0]`` as :func:`plan_threading`'s
    ``start_point``, SKT 0 is that planner's SKT (when its first path survives). SKT ``i``
    depends only on the SKTs before it, not on how many are asked for. Raises
    :class:`ThreadingFailed` (before the first yield) when no tree leaves any release: then
    no SKT exists."""
    starts = np.asarray(starts, float).reshape(-1, 3)
    check = Checker(collides, s)
    sampler = Sampler(sample_start, sample_near, lower, upper, s,
                      threading_plane(goal) if s.plane_bias > 0 else None, sample_route)
    for lead, a0, r0 in releases(goal[:3, 3], unit(goal[:3, 0]), check, s):
        tree = Tree(lead, a0, r0, lower, upper, check, s)
        leaf = tree.grow(in_start, sampler, rng, s.max_checks)
        if leaf is not None:
            break
    else:
        raise ThreadingFailed("the tree could not leave any clear release", "stuck")
    leaf_budget = max(STUCK_CHECKS, int(LEAF_BUDGET_SHARE * s.max_checks))
    misses = 0  # the current tree's leaves that collided once resampled, in a row
    for i, start in enumerate(starts):
        end = s.max_checks if i == 0 else check.n + s.max_checks  # each SKT's budget
        dense, rejected, reason = None, 0, "no_path"
        while check.n < end:
            if leaf is None:
                fresh = misses >= MISSES_PER_TREE  # its trunk does not survive resampling
                if fresh:
                    tree, misses = Tree(lead, a0, r0, lower, upper, check, s), 0
                try:
                    leaf = tree.grow(in_start, sampler, rng, min(
                        end, check.n + (s.max_checks if fresh else leaf_budget)), stuck=False)
                except ThreadingFailed:
                    misses = MISSES_PER_TREE  # this tree gives no more leaves: a fresh one
                    continue
            # a start whose joined paths keep colliding once resampled gives way to SKT 0's
            target = start if rejected < START_TRIES else starts[0]
            dense, leaf = read_out(tree, leaf, target, check, s, rng), None
            if dense is not None:
                misses = 0
                break
            misses, rejected = misses + 1, rejected + 1
        if dense is None and rejected:
            reason = "resample_collision"
        yield dense, (None if dense is not None else reason), check.n
