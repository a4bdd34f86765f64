"""Semantic keypoint poses from simulated hangs (paper §III-A, Fig. 3c).

An object hung on the test rod was threaded onto it from the rod's free end, i.e. it moved
along −x (toward the wall) into the hang. ``P_hang`` is its contact point at the hanging
pose; ``P_front`` the same point with the object moved back in front along that approach.
The keypoint frame is the SKT rule applied to the motion ``P_hang − P_front``:
x = unit motion, y = x × g, z = x × y — expressed in the object's frame.
"""

from dataclasses import dataclass

import numpy as np

from skt_lib.geometry.se3 import skt_rotation, transform_points

ROD_APPROACH = np.array([-1.0, 0.0, 0.0])  # threading onto the rod, toward the wall


@dataclass(frozen=True, eq=False)
class Keypoint:
    position: np.ndarray  # (3,) object frame, m
    rotation: np.ndarray  # (3, 3) object frame, columns = keypoint axes
    p_hang: np.ndarray  # (3,) rod (support) frame
    p_front: np.ndarray  # (3,) rod (support) frame


def keypoint_from_hang(t_hang: np.ndarray, contact_object, front_offset: float,
                       approach=ROD_APPROACH) -> Keypoint:
    """Keypoint of an object hung at ``t_hang`` (4×4, object link frame → rod frame) with
    contact point ``contact_object`` (3,) in its own frame."""
    contact_object = np.asarray(contact_object, dtype=np.float64)
    if contact_object.shape != (3,) or not np.isfinite(contact_object).all():
        raise ValueError(f"contact_object: expected 3 finite values, got {contact_object}")
    if front_offset <= 0:
        raise ValueError("front_offset: must be positive")
    approach = np.asarray(approach, float) / np.linalg.norm(approach)
    p_hang = transform_points(t_hang, contact_object[None])[0]
    p_front = p_hang - front_offset * approach
    r_rod = skt_rotation(p_hang - p_front)
    return Keypoint(contact_object, t_hang[:3, :3].T @ r_rod, p_hang, p_front)


def orthonormality_error(r: np.ndarray) -> float:
    """max(|RᵀR − I|, |det R − 1|): 0 for a proper rotation."""
    r = np.asarray(r, dtype=np.float64)
    return float(max(np.abs(r.T @ r - np.eye(3)).max(), abs(np.linalg.det(r) - 1.0)))
