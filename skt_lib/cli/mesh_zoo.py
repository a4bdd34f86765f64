"""A zoo of meshes a user might bring to ``skt import-support`` / ``skt import-object``:
the generator's own families at three resolutions (up to ≥ 250k faces), hooks no family
makes (forks with two and three prongs, a pigtail, a flat spiral, coat hooks, a rack,
knobbed pegs), meshes with small holes and several bodies, a closed one with a hairline
slit, millimetres, rotated frames, and objects (mugs with thin handles, scissors, rings);
with the inputs that must be refused.

Every mesh is built here, from the project's own primitives (:mod:`skt_lib.geometry.convex`)
and trimesh, so the tests write the zoo themselves. Each :class:`Case` says what a correct
importer does with it: ``"import"`` or ``"refuse"`` (one ``ERROR:`` line, exit code 2).

    .venv/bin/python -m skt_lib.cli.mesh_zoo FOLDER     # writes every case's mesh, lists them
"""

import math
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet_data
import trimesh

from skt_lib.cli.example_hooks import coat_hook, ring_hook
from skt_lib.config.params_file import load_params
from skt_lib.geometry.convex import Mesh, box, sphere, tube, union
from skt_lib.geometry.objects import sample_object
from skt_lib.geometry.supports import PLATE_THICKNESS_M, _Path

WALL = (PLATE_THICKNESS_M, 0.0, 0.0)
#: Faces the densest resolution of a family reaches at least.
DENSE_FACES = 250_000


@dataclass(frozen=True)
class Case:
    """One zoo mesh: ``build()`` gives the trimesh (support or object frame as the file
    says, units ``units``), written as ``<name>.<fmt>``; ``args`` are the import command's
    extra options; ``expect`` is ``"import"`` or ``"refuse"``; a refusal's ``ERROR:`` line
    contains ``reason``."""

    name: str
    kind: str  # support | object
    build: Callable[[], trimesh.Trimesh | bytes]
    expect: str = "import"
    args: tuple[str, ...] = ()
    reason: str = ""
    fmt: str = "stl"
    dense: bool = False

    def write(self, folder: Path) -> Path:
        path = Path(folder) / f"{self.name}.{self.fmt}"
        mesh = self.build()
        if isinstance(mesh, bytes):
            path.write_bytes(mesh)
        else:
            mesh.export(path)
        return path


# ---------------------------------------------------------------- builders
def _tm(mesh: Mesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


def _plate(z_lo: float, z_hi: float, half_y: float = 0.02) -> Mesh:
    return box([PLATE_THICKNESS_M / 2, 0.0, (z_lo + z_hi) / 2],
               [PLATE_THICKNESS_M / 2, half_y, (z_hi - z_lo) / 2])


def _hook(strokes, radius: float, knobs=(), z=(-0.03, 0.03), half_y: float = 0.02,
          square: bool = False) -> trimesh.Trimesh:
    parts = [_plate(*z, half_y)]
    for pts in strokes:
        parts += tube(np.asarray(pts, float), radius, square)
    parts += [sphere(c, r) for c, r in knobs]
    return _tm(union(parts))


def _subdivided(mesh: trimesh.Trimesh, min_faces: int,
                kind: str = "support") -> trimesh.Trimesh:
    """``mesh`` Loop-subdivided until it has ``min_faces`` triangles: a smooth, truly curved
    dense surface (what a fine CAD export or a scan gives), not a flat split of the same
    triangles that simplification would just undo."""
    mesh = trimesh.Trimesh(mesh.vertices, mesh.faces)  # merged: Loop needs shared vertices
    v, f = mesh.vertices, mesh.faces
    while len(f) < min_faces:
        v, f = trimesh.remesh.subdivide_loop(v, f)
    if kind == "support":  # smoothing rounds the plate's back off the wall: back onto it
        v = v - [v[:, 0].min(), 0.0, 0.0]
    return trimesh.Trimesh(v, f, process=False)


def j_hook() -> trimesh.Trimesh:
    return _hook([_Path(WALL, -4).straight(0.06).arc(0.018, 120).straight(0.01).array()], 0.004)


def l_hook() -> trimesh.Trimesh:
    return _hook([_Path(WALL, 0).straight(0.07).arc(0.006, 90).straight(0.012).array()], 0.004,
                 square=True)


def knob_peg(disk: bool = False) -> trimesh.Trimesh:
    pts = _Path(WALL, 8).straight(0.09).array()
    if not disk:
        return _hook([pts], 0.004, knobs=[(tuple(pts[-1]), 0.009)])
    d = pts[-1] - pts[-2]
    d /= np.linalg.norm(d)
    return _tm(union([_plate(-0.03, 0.03), *tube(pts, 0.004, False),
                      *tube(np.array([pts[-1] - 0.002 * d, pts[-1] + 0.002 * d]), 0.011, False)]))


def cup_hook() -> trimesh.Trimesh:
    """A screw-in cup hook: a short stem and a round J, opening up."""
    return _hook([_Path(WALL, 0).straight(0.035).arc(0.013, 170).array()], 0.0025)


def pigtail() -> trimesh.Trimesh:
    """An arm that curls up, over and back past itself, pitched sideways (a helix turn)."""
    pts = _Path(WALL, -3).straight(0.05).arc(0.016, 330).array()
    n_arc = len(pts) - 2
    pts[2:, 1] = np.linspace(0.0, 0.014, n_arc)
    return _hook([pts], 0.0035)


def fork(n_prongs: int, spread_deg: float = 25.0) -> trimesh.Trimesh:
    """A stem from the wall that splits into prongs diverging sideways, tips upturned."""
    split = np.array([0.04, 0.0, 0.0])
    strokes = [np.array([WALL, split])]
    angles = np.linspace(-spread_deg, spread_deg, n_prongs) if n_prongs > 1 else [0.0]
    for a in np.radians(angles):
        d = np.array([math.cos(a), math.sin(a), 0.0])
        end = split + 0.06 * d
        strokes.append(np.array([split, end, end + [0.008 * d[0], 0.008 * d[1], 0.018]]))
    return _hook(strokes, 0.004, half_y=0.03)


def flat_spiral() -> trimesh.Trimesh:
    """A short stem ending in a spiral in the horizontal plane (a decorative coat hook):
    the stem meets the spiral's outer end, next to the wall."""
    t = np.linspace(0, 3 * np.pi, 40)
    r = 0.008 + 0.004 * t / np.pi
    c = np.array([0.065, 0.0, 0.0])
    spiral = c + np.stack([r * np.cos(t), r * np.sin(t), np.zeros_like(t)], 1)
    return _hook([np.array([WALL, spiral[-1]]), spiral[::-1]], 0.003)


def rack(n: int = 4) -> trimesh.Trimesh:
    ys = np.linspace(-0.06, 0.06, n)
    rail = np.array([[0.02, -0.07, 0.0], [0.02, 0.07, 0.0]])
    stands = [np.array([[PLATE_THICKNESS_M, y, 0.0], [0.02, y, 0.0]]) for y in (-0.07, 0.07)]
    pegs = [_Path((0.02, y, 0.0), 15).straight(0.06).array() for y in ys]
    return _hook([rail, *stands, *pegs], 0.004, half_y=0.08)


def with_small_holes(mesh: trimesh.Trimesh, n: int = 3) -> trimesh.Trimesh:
    """``mesh`` with ``n`` faces far from each other removed: small open holes to cap."""
    mesh = mesh.copy()
    keep = np.ones(len(mesh.faces), bool)
    keep[np.linspace(0, len(mesh.faces) - 1, n + 2).astype(int)[1:-1]] = False
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)


def drilled_peg() -> trimesh.Trimesh:
    """A square peg (10 mm) rising 10°, a 3 mm hole drilled through it: a genus-1 solid."""
    tilt = trimesh.transformations.rotation_matrix(math.radians(-10), [0, 1, 0], [0.01, 0, 0])
    peg = trimesh.creation.box(extents=(0.08, 0.010, 0.010))
    peg.apply_translation((0.05, 0.0, 0.0))
    peg.apply_transform(tilt)
    drill = trimesh.creation.cylinder(0.0015, height=0.04, sections=24)
    drill.apply_translation((0.06, 0.0, 0.0))
    drill.apply_transform(tilt)
    solid = trimesh.boolean.union([_tm(_plate(-0.03, 0.03)), peg], engine="manifold")
    return trimesh.boolean.difference([solid, drill], engine="manifold")


def slit_hook(gap_m: float = 15e-9) -> trimesh.Trimesh:
    """A flat-cut hook (8 mm thick: plate, arm, upturned tip) with a hairline slit ``gap_m``
    wide up into its plate from the lower edge: one closed body whose surface passes within
    ``gap_m`` of itself, its vertices across the slit that close (a weld by distance alone
    pinches them into non-manifold edges)."""
    a, b = 0.005 - gap_m / 2, 0.005 + gap_m / 2
    xs, zs = (0.0, a, b, PLATE_THICKNESS_M, 0.072, 0.08), (-0.03, -0.015, -0.004, 0.004, 0.03)
    cells = [(i, j) for i in range(3) for j in range(4) if (i, j) != (1, 0)]  # the slit: (1, 0)
    cells += [(3, 2), (4, 2), (4, 3)]  # the arm, the tip
    index: dict = {}
    quads = [((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)) for i, j in cells]
    tris = [[index.setdefault(c, len(index)) for c in (q[0], *pair)] for q in quads
            for pair in ((q[1], q[2]), (q[2], q[3]))]
    xz = np.array([(xs[i], zs[j]) for i, j in index])  # dicts keep insertion order
    m = trimesh.creation.extrude_triangulation(xz, np.array(tris), 0.008)
    x, z, y = m.vertices.T  # the profile's plane is the support's x-z
    return trimesh.Trimesh(np.c_[x, y - 0.004, z], m.faces[:, ::-1], process=False)


def two_bodies() -> trimesh.Trimesh:
    """A peg and a knob written as two separate, overlapping bodies."""
    pts = _Path(WALL, 10).straight(0.08).array()
    peg = _hook([pts], 0.004)
    knob = trimesh.creation.icosphere(3, 0.009)
    knob.apply_translation(pts[-1])
    return trimesh.util.concatenate([peg, knob])


def in_mm(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(mesh.vertices * 1000.0, mesh.faces, process=False)


#: The rotated-frame case: the wall's outward normal is the mesh's -y, up is +z, and the
#: mount sits 50 mm up (what ``--mount 0 0 0.05 --out-axis 0 -1 0`` undoes).
ROTATED_ARGS = ("--mount", "0", "0", "0.05", "--out-axis", "0", "-1", "0")


def rotated(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    rot = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # x -> -y
    return trimesh.Trimesh(mesh.vertices @ rot.T + [0.0, 0.0, 0.05], mesh.faces, process=False)


def half(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Only the faces above z = 0: a mesh with a large open cut."""
    keep = mesh.vertices[mesh.faces][:, :, 2].min(1) > 0.0
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)


def moved(mesh: trimesh.Trimesh, offset) -> trimesh.Trimesh:
    return trimesh.Trimesh(mesh.vertices + offset, mesh.faces, process=False)


def generated_object(category: str, seed: int) -> trimesh.Trimesh:
    """An object the generator makes (its convex parts' union), object frame."""
    p = load_params(Path(__file__).resolve().parents[2] / "params.yaml").mesh_gen
    shape = sample_object(np.random.default_rng(seed), category, p)
    return _tm(union(list(shape.parts)))


def thin_handle_mug() -> trimesh.Trimesh:
    body = trimesh.creation.cylinder(0.035, 0.09, sections=48)
    handle = trimesh.creation.torus(0.022, 0.0025, major_sections=48, minor_sections=12)
    handle.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    handle.apply_translation((0.053, 0.0, 0.0))
    return trimesh.boolean.union([body, handle], engine="manifold")


def scissors() -> trimesh.Trimesh:
    rings = []
    for y in (-0.018, 0.018):
        ring = trimesh.creation.torus(0.013, 0.003, major_sections=40, minor_sections=12)
        ring.apply_translation((0.0, y, 0.0))
        rings.append(ring)
    blade = trimesh.creation.box(extents=(0.11, 0.012, 0.004))
    blade.apply_translation((0.07, 0.0, 0.0))
    bridge = trimesh.creation.box(extents=(0.02, 0.04, 0.004))  # clear of the finger holes
    bridge.apply_translation((0.022, 0.0, 0.0))
    return trimesh.boolean.union([*rings, blade, bridge], engine="manifold")


def ring(major: float = 0.02, minor: float = 0.004) -> trimesh.Trimesh:
    return trimesh.creation.torus(major, minor, major_sections=64, minor_sections=16)


def pybullet_mug() -> trimesh.Trimesh:
    path = Path(pybullet_data.getDataPath()) / "objects" / "mug.obj"
    return trimesh.load(path, force="mesh", process=False)


# ---------------------------------------------------------------- the zoo
def _families() -> list[Case]:
    out = []
    for fam, build in (("j_hook", j_hook), ("l_hook", l_hook), ("knob_peg", knob_peg)):
        out.append(Case(f"{fam}_coarse", "support", build))
        out.append(Case(f"{fam}_fine", "support", lambda b=build: _subdivided(b(), 25_000),
                        dense=True, fmt="ply"))
        out.append(Case(f"{fam}_250k", "support", lambda b=build: _subdivided(b(), DENSE_FACES),
                        dense=True))
    return out


def cases() -> list[Case]:
    """Every zoo case, in a fixed order."""
    return [
        *_families(),
        Case("cup_hook", "support", cup_hook),
        Case("cup_hook_250k", "support", lambda: _subdivided(cup_hook(), DENSE_FACES), dense=True),
        Case("pigtail", "support", pigtail),
        Case("fork_2", "support", lambda: fork(2)),
        Case("fork_3", "support", lambda: fork(3, spread_deg=40.0)),
        Case("flat_spiral", "support", flat_spiral),
        Case("coat_hook", "support", coat_hook),
        Case("ring_hook", "support", ring_hook),
        Case("rack", "support", rack),
        Case("disk_knob_peg", "support", lambda: knob_peg(disk=True), fmt="obj"),
        Case("small_holes", "support", lambda: with_small_holes(j_hook())),
        Case("drilled_peg", "support", drilled_peg, fmt="obj"),
        Case("two_bodies", "support", two_bodies, fmt="obj"),
        Case("slit_hook", "support", slit_hook),
        Case("j_hook_mm", "support", lambda: in_mm(j_hook()), args=("--units", "mm")),
        Case("j_hook_rotated", "support", lambda: rotated(j_hook()), args=ROTATED_ARGS,
             fmt="glb"),
        # refusals
        Case("mm_as_metres", "support", lambda: in_mm(j_hook()), "refuse", reason="--units mm"),
        Case("behind_wall", "support", lambda: moved(j_hook(), (-0.02, 0, 0)), "refuse",
             reason="behind the wall"),
        Case("floating", "support", lambda: moved(j_hook(), (0.04, 0, 0)), "refuse",
             reason="in front of the wall"),
        Case("half_mesh", "support", lambda: half(ring_hook()), "refuse", reason="not watertight"),
        Case("not_a_mesh", "support", lambda: b"solid nothing\nthis is not an STL\n", "refuse",
             reason="no triangles"),
        # objects
        Case("generated_mug", "object", lambda: generated_object("mug", 1), fmt="obj"),
        Case("generated_scissor", "object", lambda: generated_object("scissor", 2), fmt="obj"),
        Case("thin_handle_mug", "object", thin_handle_mug),
        Case("thin_handle_mug_250k", "object",
             lambda: _subdivided(thin_handle_mug(), DENSE_FACES, "object"), dense=True),
        Case("scissors", "object", scissors, fmt="ply"),
        Case("ring", "object", ring),
        Case("pybullet_mug", "object", pybullet_mug, fmt="obj"),
        Case("mug_mm", "object", lambda: in_mm(thin_handle_mug()), args=("--units", "mm")),
        Case("solid_ball", "object", lambda: trimesh.creation.icosphere(3, 0.03), "refuse",
             reason="no through-hole"),
        Case("ring_too_small", "object", lambda: ring(0.006, 0.002), "refuse",
             reason="admits a rod"),
    ]


@dataclass(frozen=True)
class Outcome:
    """What ``skt import-<kind>`` did with a case: exit code, wall seconds, the ``ERROR:``
    lines of its stderr, its stdout."""

    case: Case
    returncode: int
    seconds: float
    errors: tuple[str, ...]
    stdout: str

    @property
    def as_expected(self) -> bool:
        if self.case.expect == "import":
            return self.returncode == 0
        return (self.returncode == 2 and len(self.errors) == 1
                and self.case.reason in self.errors[0])


def run_case(case: Case, folder: Path, data_root: Path, params: Path,
             timeout_s: float = 600.0) -> Outcome:
    """Write ``case``'s mesh into ``folder`` and import it with the ``skt`` command line in
    a process of its own (an abort there cannot take the caller down)."""
    path = case.write(folder)
    cmd = [sys.executable, "-m", "skt_lib.cli.main", f"import-{case.kind}", str(path),
           "--name", case.name, "--params", str(params), "--data-root", str(data_root),
           *case.args]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    seconds = time.perf_counter() - t0
    errors = tuple(line for line in proc.stderr.splitlines() if line.startswith("ERROR:"))
    return Outcome(case, proc.returncode, seconds, errors, proc.stdout)


#: The pipeline stages an import reads (the reference object, the probes, their keypoints).
IMPORT_STAGES = ("mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts")


def linked_root(base: Path, name: str, data: Path) -> Path:
    """A data root of its own for one import, ``base/name``: the stages of ``data`` that an
    import reads, linked (nothing copied; the import writes only ``user/``)."""
    root = Path(base) / name
    root.mkdir(parents=True)
    for stage in IMPORT_STAGES:
        (root / stage).symlink_to((Path(data) / stage).resolve(), target_is_directory=True)
    return root


def bench_dense_imports(params: Path, data: Path, tmp: Path) -> dict:
    """``make bench``'s figures: the ≥ 250k-face cases imported one at a time, each a fresh
    process (its start included: what a user waits for)."""
    seconds, failed = {}, {}
    for case in [c for c in cases() if c.dense and c.name.endswith("_250k")]:
        out = run_case(case, tmp, linked_root(tmp / "roots", case.name, data), params)
        if out.returncode == 0:
            seconds[case.name] = out.seconds
        else:
            failed[case.name] = (out.errors or (f"exit code {out.returncode}",))[-1]
    return {"import_dense_s_median": float(np.median(list(seconds.values()))) if seconds else None,
            "import_dense_s": seconds, "import_dense_failed": failed}


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    folder = Path(args[0] if args else "mesh_zoo")
    folder.mkdir(parents=True, exist_ok=True)
    for case in cases():
        path = case.write(folder)
        print(f"{path}  {case.kind} {case.expect} {' '.join(case.args)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
