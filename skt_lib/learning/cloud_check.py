"""The cloud check: how deep the reference ring, carried along an SKT, cuts into the cloud
the SKT was predicted from.

SCTDN's read-out (:class:`~skt_lib.learning.predictor.SktPredictor`) can offer several
candidate SKTs — the deformed trajectory and the aligned template of its most probable
families — and keep the one the observed points say is clearest. Only the input cloud is
used: no mesh, no ground truth.

The ring is the reference object's (:func:`skt_lib.geometry.objects.reference_object`): a
torus of centreline radius :data:`REFERENCE_RING_RADIUS_M` and section
:data:`REFERENCE_SECTION_M`, its axis the keypoint frame's x (the motion), its centre below
the keypoint along the frame's z by the inner radius (the keypoint is the aperture's top,
where the support carries the ring). It is placed at every waypoint's SKT frame
(:func:`skt_lib.geometry.skt.skt_frames`) and at ``samples_per_segment`` points between
waypoints (positions interpolated, the segment's first frame). A cloud point at distance
``d`` from the ring's centreline penetrates by ``max(0, section − d)``; the score is the sum
of squared penetrations (m²) over every placement and point, so a path that grazes the
support scores far below one that cuts through it. Points the camera did not see cannot
count: the check can clear a path that cuts through the back of a support.
"""

import numpy as np
from scipy.spatial import cKDTree

from skt_lib.geometry.objects import REFERENCE_RING_RADIUS_M, REFERENCE_SECTION_M
from skt_lib.geometry.skt import skt_frames

#: The ring centre's depth below the keypoint (m): the ring's inner radius.
RING_CENTRE_BELOW_M = REFERENCE_RING_RADIUS_M - REFERENCE_SECTION_M
#: Ring placements per SKT segment (waypoints ~6 mm apart at T = 40, the ring's section 4 mm).
SAMPLES_PER_SEGMENT = 2


def ring_placements(positions: np.ndarray, samples_per_segment: int = SAMPLES_PER_SEGMENT,
                    rotations: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Ring centres ``(M, 3)`` and axes ``(M, 3)`` along ``positions (T, 3)`` (ξ_0 first),
    ``M = (T − 1) · samples_per_segment + 1``; ``rotations (T, 3, 3)``: the SKT frames'
    rotations where the caller has them (default: :func:`skt_frames` of ``positions``)."""
    if samples_per_segment < 1:
        raise ValueError(f"samples_per_segment: need ≥ 1, got {samples_per_segment}")
    positions = np.asarray(positions, dtype=np.float64)
    rot = skt_frames(positions)[:, :3, :3] if rotations is None else np.asarray(rotations, float)
    if rot.shape != (len(positions), 3, 3):
        raise ValueError(f"rotations: expected {(len(positions), 3, 3)}, got {rot.shape}")
    s = np.arange(samples_per_segment) / samples_per_segment
    seg = positions[:-1, None] + s[None, :, None] * (positions[1:] - positions[:-1])[:, None]
    at = np.concatenate([seg.reshape(-1, 3), positions[-1:]])
    idx = np.r_[np.repeat(np.arange(len(positions) - 1), samples_per_segment), len(positions) - 1]
    return at - RING_CENTRE_BELOW_M * rot[idx, :, 2], rot[idx, :, 0]


def ring_penetrations(candidates: list[np.ndarray], cloud: np.ndarray,
                      samples_per_segment: int = SAMPLES_PER_SEGMENT,
                      rotations: list[np.ndarray] | None = None) -> np.ndarray:
    """Per candidate SKT ``(T, 3)``: the sum over ring placements and points of ``cloud (N,
    3)`` of the squared penetration (m²) of the reference ring carried along it; 0 where no
    point is inside the ring's material. All candidates in one neighbour query.
    ``rotations``: each candidate's SKT-frame rotations, as in :func:`ring_placements`."""
    if not len(candidates):
        raise ValueError("candidates: need at least one SKT")
    if rotations is not None and len(rotations) != len(candidates):
        raise ValueError(f"rotations: one per candidate, got {len(rotations)} for "
                         f"{len(candidates)}")
    placed = [ring_placements(c, samples_per_segment, r)
              for c, r in zip(candidates, rotations or [None] * len(candidates))]
    centres = np.concatenate([c for c, _ in placed])
    axes = np.concatenate([a for _, a in placed])
    owner = np.repeat(np.arange(len(placed)), [len(c) for c, _ in placed])
    cloud = np.asarray(cloud, dtype=np.float64)
    pairs = cKDTree(centres).sparse_distance_matrix(
        cKDTree(cloud), REFERENCE_RING_RADIUS_M + REFERENCE_SECTION_M, output_type="ndarray")
    i, j = pairs["i"], pairs["j"]
    v = cloud[j] - centres[i]
    h = np.einsum("ij,ij->i", v, axes[i])
    slab = np.abs(h) < REFERENCE_SECTION_M  # the ring's material lies within the slab
    i, v, h = i[slab], v[slab], h[slab]
    r = np.linalg.norm(v - h[:, None] * axes[i], axis=1)
    pen = np.maximum(REFERENCE_SECTION_M - np.hypot(h, r - REFERENCE_RING_RADIUS_M), 0.0)
    return np.bincount(owner[i], pen * pen, minlength=len(placed))


def clearest(candidates: list[np.ndarray], cloud: np.ndarray,
             samples_per_segment: int = SAMPLES_PER_SEGMENT,
             rotations: list[np.ndarray] | None = None) -> tuple[int, np.ndarray]:
    """Index of the candidate SKT ``(T, 3)`` with the least :func:`ring_penetrations` into
    ``cloud`` (the first of equals: pass candidates in order of preference), and every
    candidate's score."""
    scores = ring_penetrations(candidates, cloud, samples_per_segment, rotations)
    return int(np.argmin(scores)), scores
