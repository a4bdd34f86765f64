"""Affordance maps on a partial cloud (paper §V-B).

contact map  M_cp(i)  = exp(−|p_i − p_c|² / 2σ²), p_c the cloud point nearest the contact
segmentation M_seg(i) = max_j exp(−|p_i − q_j|² / 2σ²), q_j the cloud points nearest the
                        SKT waypoints of the hanging part
affordance   A        = α·M_cp + β·M_seg
Points are ``(N, 3)`` support frame, metres; maps ``(N,)`` float32 in [0, 1 (α + β)].
"""

import numpy as np
from scipy.spatial import cKDTree


def gaussian(d: np.ndarray, sigma: float) -> np.ndarray:
    return np.exp(-0.5 * (np.asarray(d) / sigma) ** 2)


def contact_map(points: np.ndarray, contact: np.ndarray, sigma: float) -> tuple[np.ndarray, int]:
    """(M_cp, index of the cloud point nearest ``contact``)."""
    k = int(np.argmin(np.linalg.norm(points - contact, axis=1)))
    return gaussian(np.linalg.norm(points - points[k], axis=1), sigma), k


def segmentation_map(points: np.ndarray, waypoints: np.ndarray, sigma: float) -> np.ndarray:
    """Max of Gaussians at the cloud points nearest each waypoint ``(M, 3)``."""
    tree = cKDTree(points)
    _, anchors = tree.query(waypoints)
    anchors = np.unique(anchors)
    d = np.linalg.norm(points[:, None, :] - points[anchors][None], axis=2).min(axis=1)
    return gaussian(d, sigma)


def segmentation_map_naive(points: np.ndarray, waypoints: np.ndarray, sigma: float) -> np.ndarray:
    """Reference for :func:`segmentation_map`: explicit loops."""
    anchors = {int(np.argmin([np.linalg.norm(p - w) for p in points])) for w in waypoints}
    out = np.zeros(len(points))
    for i, p in enumerate(points):
        out[i] = max(np.exp(-0.5 * (np.linalg.norm(p - points[a]) / sigma) ** 2) for a in anchors)
    return out


def affordance(points, contact, waypoints, sigma: float, alpha: float, beta: float):
    """(A, M_cp, M_seg, contact index), maps as float32."""
    m_cp, k = contact_map(points, contact, sigma)
    m_seg = segmentation_map(points, waypoints, sigma)
    return ((alpha * m_cp + beta * m_seg).astype(np.float32), m_cp.astype(np.float32),
            m_seg.astype(np.float32), k)


def hanging_part(keypoints: np.ndarray, length: float) -> np.ndarray:
    """The waypoints of an SKT ``(N, 3)`` (ξ_0 first) within ``length`` of arc from ξ_0."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(keypoints, axis=0), axis=1))])
    return keypoints[s <= length]
