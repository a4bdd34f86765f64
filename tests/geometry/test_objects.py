"""Objects: every aperture admits the documented rod, proven in PyBullet by a collision-free
insertion along the aperture axis; a rod just wider than the clearance collides."""

import numpy as np
import pybullet as pb
import pytest

from skt_lib.config import OBJECT_CATEGORIES
from skt_lib.geometry.build import ObjectTask, build_object
from skt_lib.geometry.convex import union
from skt_lib.geometry.objects import aperture_clearance, reference_object, ring, sample_object
from skt_lib.seeding import item_rng


def test_clearance_of_a_round_ring_is_analytic():
    a, w = 0.02, 0.004
    parts = ring(a, a, w, square=False)
    # chord midpoint at a·cos(π/16); the capsule reaches at most w further in (its
    # icosphere caps are inscribed in the sphere of radius w, so slightly less)
    c = aperture_clearance(parts)
    lower = a * np.cos(np.pi / 16) - w
    assert lower <= c <= lower + 0.1 * w


def _sweep_rod(urdf: str, rod_radius: float) -> bool:
    """True when a rod along x slides from x=-0.2 to x=+0.2 through the origin touching nothing."""
    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(urdf, useFixedBase=True, physicsClientId=cid)
        quat = pb.getQuaternionFromEuler([0, np.pi / 2, 0])  # cylinder z axis -> x
        col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=rod_radius, height=0.1,
                                      physicsClientId=cid)
        rod = pb.createMultiBody(0, col, basePosition=[-0.2, 0, 0], baseOrientation=quat,
                                 physicsClientId=cid)
        for x in np.arange(-0.2, 0.2001, 0.002):
            pb.resetBasePositionAndOrientation(rod, [x, 0, 0], quat, physicsClientId=cid)
            if pb.getClosestPoints(body, rod, 0.0, physicsClientId=cid):
                return False
        return True
    finally:
        pb.disconnect(cid)


@pytest.mark.parametrize("category", [*OBJECT_CATEGORIES, "reference"])
def test_aperture_admits_documented_rod_by_insertion(category, tiny_params, tmp_path):
    p = tiny_params.mesh_gen
    row = build_object(ObjectTask(3, category, 0, p, str(tmp_path)))
    urdf = str(tmp_path / row["urdf_path"])
    assert row["aperture_clearance_m"] >= p.object_rod_radius_m
    assert _sweep_rod(urdf, p.object_rod_radius_m)
    # negative control: the same sweep with a rod 2 mm wider than the clearance collides
    assert not _sweep_rod(urdf, row["aperture_clearance_m"] + 0.002)


def test_objects_are_deterministic_and_categories_differ(tiny_params):
    p = tiny_params.mesh_gen
    a = sample_object(item_rng(1, "o", "x"), "mug", p)
    b = sample_object(item_rng(1, "o", "x"), "mug", p)
    assert all(np.array_equal(u.vertices, v.vertices) for u, v in zip(a.parts, b.parts))
    # every category draws a different shape from the same generator state: compare a
    # signature (aperture kind, part count, bounding box, volume) pairwise
    sig = {}
    for c in OBJECT_CATEGORIES:
        o = sample_object(item_rng(1, "o", "x"), c, p)
        assert o.category == c
        v = np.vstack([q.vertices for q in o.parts])
        sig[c] = (o.aperture, len(o.parts), np.round(np.ptp(v, axis=0), 4).tolist(),
                  round(sum(q.volume for q in o.parts), 9))
    assert len({repr(x) for x in sig.values()}) == len(OBJECT_CATEGORIES), sig
    # and another generator state draws another mug
    c = sample_object(item_rng(2, "o", "x"), "mug", p)
    assert not all(np.array_equal(u.vertices, v.vertices) for u, v in zip(a.parts, c.parts))
    with pytest.raises(ValueError, match="category"):
        sample_object(item_rng(1, "o", "x"), "teapot", p)


def test_reference_object_is_one_fixed_solid():
    ref = reference_object()
    u = union(list(ref.parts))
    assert u.to_trimesh().is_watertight and u.volume > 0
    assert aperture_clearance(ref.parts) > 0.02
