"""Two hook meshes no ``mesh_gen`` family makes, built with trimesh (support frame, metres):
a coat hook with two prongs at different heights and an open ring on a stem. The README's
walk-through and the import tests use them.

    .venv/bin/python -m skt_lib.cli.example_hooks [FOLDER]   # writes coat_hook.stl, ring_hook.stl
"""

import sys
from pathlib import Path

import numpy as np
import trimesh


def _union(parts) -> trimesh.Trimesh:
    return trimesh.boolean.union(parts, engine="manifold")


def _plate(z_lo: float, z_hi: float) -> trimesh.Trimesh:
    plate = trimesh.creation.box(extents=(0.01, 0.04, z_hi - z_lo))
    plate.apply_translation((0.005, 0.0, (z_lo + z_hi) / 2))
    return plate


def coat_hook() -> trimesh.Trimesh:
    """A plate with a long lower prong and a short upper prong at 40°. The lower prong runs
    out 6 cm sloping down 8°, then turns up 53° to a ball end, as a coat hook's does: what
    hangs on it settles in the bend, 5 cm from the wall, so a mug's body hangs clear of the
    wall. (A prong rising straight from the plate slides everything back against the plate,
    where a mug 8 cm across meets the wall on its way in.)"""
    bend, tip = (0.06, 0, -0.008), (0.075, 0, 0.012)
    lower = trimesh.creation.cylinder(0.005, segment=[(0.005, 0, 0.0), bend], sections=32)
    turn = trimesh.creation.cylinder(0.005, segment=[bend, tip], sections=32)
    elbow = trimesh.creation.icosphere(3, 0.005)
    elbow.apply_translation(bend)
    ball = trimesh.creation.icosphere(3, 0.008)
    ball.apply_translation(tip)
    upper = trimesh.creation.cylinder(0.004, segment=[(0.005, 0, 0.05), (0.045, 0, 0.084)],
                                      sections=32)
    return _union([_plate(-0.02, 0.07), lower, turn, elbow, ball, upper])


def _tube(points: np.ndarray, radius: float) -> list[trimesh.Trimesh]:
    """Cylinders between consecutive ``points`` and balls at the joints."""
    parts = [trimesh.creation.cylinder(radius, segment=[a, b], sections=24)
             for a, b in zip(points[:-1], points[1:])]
    for p in points:
        ball = trimesh.creation.icosphere(2, radius)
        ball.apply_translation(p)
        parts.append(ball)
    return parts


def ring_hook(gap_deg: float = 80.0) -> trimesh.Trimesh:
    """A stem out of the wall ending in a vertical ring (x–z plane, 22 mm radius) that is
    open at the top: from the stem it runs down, round the front and up, stopping
    ``gap_deg`` short of the stem's side; objects enter through the opening."""
    stem = trimesh.creation.cylinder(0.005, segment=[(0.005, 0, 0.0), (0.04, 0, 0.0)],
                                     sections=32)
    centre, rho = np.array([0.062, 0.0, 0.0]), 0.022
    angles = np.radians(np.arange(180.0, 180.0 + 360.0 - gap_deg + 1e-9, 10.0))
    arc = centre + rho * np.stack([np.cos(angles), np.zeros_like(angles), np.sin(angles)], 1)
    return _union([_plate(-0.03, 0.03), stem, *_tube(arc, 0.0045)])


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    folder = Path(args[0] if args else ".")
    folder.mkdir(parents=True, exist_ok=True)
    for name, build in (("coat_hook", coat_hook), ("ring_hook", ring_hook)):
        build().export(folder / f"{name}.stl")
        print(folder / f"{name}.stl")
    return 0


if __name__ == "__main__":
    sys.exit(main())
