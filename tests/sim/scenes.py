"""Scenes for executor and predicate tests, built in code: the reference ring and a
hand-written support (wall plate + a straight peg angled up + a short tab on the plate)."""

from pathlib import Path

import numpy as np

from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.config.sim_eval import SimEvalParams
from skt_lib.eval.protocol import trial_settings
from skt_lib.geometry.build import ObjectTask, build_object
from skt_lib.geometry.export import read_obj
from skt_lib.sim.execute import TrialSettings, TrialTask
from skt_lib.sim.grasp import grasp_candidates
from tests.conftest import TINY

PEG_ANGLE_DEG = 25.0  # above horizontal: the ≈22° outward tilt of the perturbation keeps it on
PEG_RADIUS_M = 0.005
PEG_LENGTH_M = 0.09
PLATE_M = 0.01
TAB_Y_M = 0.08  # a 1 cm bar sticking out of the plate (all of it within the plate's x range)
TAB_Z_M = 0.0
RING_INNER_M = 0.022  # reference ring: 26 mm centreline − 4 mm section
#: keypoint of the reference ring in its object frame: inner top of the aperture, x = −x
RING_KEYPOINT = np.array([[-1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, 1.0, RING_INNER_M], [0, 0, 0, 1.0]])
RING_RADIUS_M = 0.08  # bound on the farthest ring point from the keypoint


def peg_axis() -> np.ndarray:
    a = np.radians(PEG_ANGLE_DEG)
    return np.array([np.cos(a), 0.0, np.sin(a)])


def peg_normal() -> np.ndarray:
    a = np.radians(PEG_ANGLE_DEG)
    return np.array([-np.sin(a), 0.0, np.cos(a)])


def write_support(directory: Path) -> str:
    """URDF of the support (support frame = URDF frame); returns its path."""
    axis = peg_axis()
    centre = np.array([PLATE_M, 0.0, 0.0]) + axis * PEG_LENGTH_M / 2
    pitch = np.pi / 2 - np.radians(PEG_ANGLE_DEG)  # cylinder z axis → peg axis

    def box(xyz, size):
        return (f'<collision><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><geometry>'
                f'<box size="{size[0]} {size[1]} {size[2]}"/></geometry></collision>')

    text = f"""<?xml version="1.0"?>
<robot name="test_support"><link name="base">
<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
{box((PLATE_M / 2, 0.0, 0.0), (PLATE_M, 0.24, 0.16))}
<collision><origin xyz="{centre[0]} {centre[1]} {centre[2]}" rpy="0 {pitch} 0"/><geometry>
<cylinder radius="{PEG_RADIUS_M}" length="{PEG_LENGTH_M}"/></geometry></collision>
{box((PLATE_M / 2, TAB_Y_M, TAB_Z_M), (PLATE_M, 0.006, 0.006))}
</link></robot>"""
    path = Path(directory) / "test_support.urdf"
    path.write_text(text)
    return str(path)


def build_ring(directory: Path) -> tuple[str, np.ndarray]:
    """(URDF path, mesh vertices (N, 3)) of the reference ring."""
    row = build_object(ObjectTask(0, "reference", 0, MeshGenParams(**TINY["mesh_gen"]), str(directory)))
    (mesh,) = read_obj(Path(directory) / row["mesh_path"])
    return str(Path(directory) / row["urdf_path"]), mesh.vertices


def straight_skt(hang_s: float = 0.07, length: float = 0.12, offset=(0.0, 0.0, 0.0),
                 T: int = 10) -> np.ndarray:
    """Positions (T, 3), ξ_0 first: the ring's keypoint ``hang_s`` along the peg, 3 mm above
    its surface, approached straight along the peg axis from ``length`` further out;
    ``offset`` shifts the whole line (support frame, m)."""
    hang = np.array([PLATE_M, 0.0, 0.0]) + hang_s * peg_axis() + (PEG_RADIUS_M + 0.003) * peg_normal()
    s = np.linspace(0.0, length, T)[:, None]
    return hang + s * peg_axis() + np.asarray(offset, float)


def settings(**changes) -> TrialSettings:
    import dataclasses

    s = trial_settings(SimEvalParams(**TINY["sim_eval"]), ContactSimParams(**TINY["contact_sim"]))
    return dataclasses.replace(s, **changes)


def ring_task(support_urdf: str, ring_urdf: str, vertices: np.ndarray, positions: np.ndarray,
              hand: str = "panda", **changes) -> TrialTask:
    s = settings(**changes)
    grasps = grasp_candidates(vertices, RING_KEYPOINT, (45.0, 30.0, 60.0), (0.0, 180.0))
    return TrialTask(f"test/{hand}", "test", "support_test", "object_reference", support_urdf,
                     ring_urdf, tuple(RING_KEYPOINT.ravel()), grasps, RING_RADIUS_M,
                     tuple(map(tuple, positions)), s, 0, {"difficulty": "easy", "category": "ring"},
                     hand)
