"""File formats for shapes: OBJ (visual), multi-object OBJ (convex collision parts), URDF.

Numbers are written with fixed formatting so the same shape gives byte-identical files.
PyBullet loads a collision OBJ with several ``o`` objects as a compound of convex hulls,
one per object: the parts are used as they are, no V-HACD.
"""

import io
from pathlib import Path

import numpy as np
import trimesh

from skt_lib.geometry.convex import Mesh
from skt_lib.io import write_text_atomic

_FMT = "%.9f"


def _obj_block(mesh: Mesh, offset: int) -> str:
    buf = io.StringIO()
    np.savetxt(buf, mesh.vertices, fmt=f"v {_FMT} {_FMT} {_FMT}")
    np.savetxt(buf, mesh.faces + 1 + offset, fmt="f %d %d %d")
    return buf.getvalue()


def obj_text(mesh: Mesh, comment: str) -> str:
    return f"# {comment}\n# units: metres\n" + _obj_block(mesh, 0)


def collision_obj_text(parts: list[Mesh], comment: str) -> str:
    out, offset = [f"# {comment}\n# units: metres; one convex part per object\n"], 0
    for k, part in enumerate(parts):
        out.append(f"o part_{k:03d}\n" + _obj_block(part, offset))
        offset += len(part.vertices)
    return "".join(out)


def read_obj(path: str | Path) -> list[Mesh]:
    """Read an OBJ written by this module: one :class:`Mesh` per ``o`` object (or one)."""
    meshes, verts, faces, base = [], [], [], 0
    for line in Path(path).read_text().splitlines():
        if line.startswith("o ") and faces:
            meshes.append(Mesh(np.array(verts), np.array(faces) - 1 - base))
            base += len(verts)
            verts, faces = [], []
        elif line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(x.split("/")[0]) for x in line.split()[1:4]])
    if faces:
        meshes.append(Mesh(np.array(verts), np.array(faces) - 1 - base))
    return meshes


def mass_properties(mesh: Mesh, density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass kg, centre of mass (3,), inertia about the COM (3, 3)) of a solid mesh."""
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    tm.density = density
    return float(tm.mass), np.asarray(tm.center_mass), np.asarray(tm.moment_inertia)


#: Absolute resolution of the centre of mass (m) and inertia (kg m²) written in URDFs: far
#: below anything that matters physically, far above summation-order noise (a symmetric
#: object's zero off-diagonal inertia, ~1e-23, would otherwise be written as that noise).
_COM_STEPS_PER_M = 1e12  # 1e-12 m
_INERTIA_STEPS_PER_UNIT = 1e15  # 1e-15 kg m²


def _quantise(x, per_unit: float) -> np.ndarray:
    return np.rint(np.asarray(x, dtype=np.float64) * per_unit) / per_unit + 0.0  # no -0.0


def urdf_text(name: str, visual: str, collision: str, mass: float, com, inertia, rgba) -> str:
    """A one-link URDF. ``mass == 0`` makes the body static in PyBullet."""
    f = lambda x: f"{x:.9g}"  # noqa: E731
    com = _quantise(com, _COM_STEPS_PER_M)
    i = _quantise(inertia, _INERTIA_STEPS_PER_UNIT)
    return f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="base">
    <inertial>
      <origin xyz="{f(com[0])} {f(com[1])} {f(com[2])}" rpy="0 0 0"/>
      <mass value="{f(mass)}"/>
      <inertia ixx="{f(i[0, 0])}" ixy="{f(i[0, 1])}" ixz="{f(i[0, 2])}" iyy="{f(i[1, 1])}" iyz="{f(i[1, 2])}" izz="{f(i[2, 2])}"/>
    </inertial>
    <visual>
      <geometry><mesh filename="{visual}"/></geometry>
      <material name="{name}_colour"><color rgba="{' '.join(f(c) for c in rgba)}"/></material>
    </visual>
    <collision>
      <geometry><mesh filename="{collision}"/></geometry>
    </collision>
  </link>
</robot>
"""


def write_shape(directory: Path, name: str, visual: Mesh, parts: list[Mesh],
                mass: float, com, inertia, rgba) -> dict[str, Path]:
    """Write ``visual.obj``, ``collision.obj`` and ``<name>.urdf`` into ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = {
        "mesh": directory / "visual.obj",
        "collision": directory / "collision.obj",
        "urdf": directory / f"{name}.urdf",
    }
    write_text_atomic(paths["mesh"], obj_text(visual, f"{name} visual mesh"))
    write_text_atomic(paths["collision"], collision_obj_text(parts, f"{name} collision parts"))
    write_text_atomic(
        paths["urdf"], urdf_text(name, "visual.obj", "collision.obj", mass, com, inertia, rgba)
    )
    return paths
