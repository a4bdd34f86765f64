"""What every ``skt`` subcommand shares: reading user files into checked arrays, progress,
and the exit-code convention (an expected error is an :class:`~skt_lib.errors.InputError`
or another :class:`~skt_lib.errors.SktError`, reported on one line with exit code 2)."""

import argparse
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import open3d as o3d
from tqdm import tqdm

from skt_lib.errors import DataError, InputError

if TYPE_CHECKING:
    from skt_lib.cli.flow_readout import FlowReadout
    from skt_lib.learning.predictor import SktPredictor

EXIT_BAD_INPUT = 2
CLOUD_SUFFIXES = (".ply", ".pcd", ".npy", ".npz", ".xyz", ".txt")
UNITS = {"m": 1.0, "mm": 0.001}


def count_arg(value: str) -> int:
    """An argparse type: a whole number from 1 to 100 (proposals, samples)."""
    try:
        n = int(value)
    except ValueError:
        n = 0
    if not 1 <= n <= 100:
        raise argparse.ArgumentTypeError(f"expected a whole number from 1 to 100, got {value!r}")
    return n


def existing_file(path: str | Path, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such {what}")
    if not p.is_file():
        raise InputError(f"{p}: not a file (expected a {what})")
    if p.stat().st_size == 0:
        raise InputError(f"{p}: empty file (expected a {what})")
    return p


def read_cloud(path: str | Path) -> np.ndarray:
    """An ``(N, 3)`` float64 array from ``.ply``/``.pcd`` (Open3D), ``.npy``/``.npz`` (an
    ``(N, 3)`` array; in an ``.npz`` the only array or the one named ``points``) or
    ``.xyz``/``.txt`` (whitespace- or comma-separated x y z rows). Rows may hold NaN: the
    cleaning drops them."""
    p = existing_file(path, "point cloud")
    suffix = p.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise InputError(f"{p}: unknown point-cloud format {suffix!r} "
                         f"(expected one of {', '.join(CLOUD_SUFFIXES)})")
    try:
        if suffix in (".ply", ".pcd"):
            pcd = o3d.io.read_point_cloud(str(p), remove_nan_points=False,
                                          remove_infinite_points=False)
            a = np.asarray(pcd.points, dtype=np.float64)
            if len(a) == 0:
                raise InputError(f"{p}: no points read (not a {suffix[1:].upper()} point cloud?)")
        elif suffix == ".npy":
            a = np.load(p, allow_pickle=False)
        elif suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                if "points" in z.files:
                    a = z["points"]
                elif len(z.files) == 1:
                    a = z[z.files[0]]
                else:
                    raise InputError(f"{p}: {len(z.files)} arrays and none named 'points'")
        else:
            a = np.loadtxt(p, delimiter="," if "," in p.read_text()[:4096] else None, ndmin=2)
    except InputError:
        raise
    except (OSError, ValueError, EOFError) as err:
        raise InputError(f"{p}: not a readable {suffix[1:]} point cloud: "
                         f"{str(err).splitlines()[0][:160]}") from None
    a = np.asarray(a)
    if a.dtype.kind not in "fiu":
        raise InputError(f"{p}: array of dtype {a.dtype}, expected numbers")
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{p}: expected an (N, 3) array of x, y, z, got shape {a.shape}")
    return a.astype(np.float64)


def read_frame(path: str | Path) -> np.ndarray:
    """A 4×4 camera-to-support transform from JSON: a list of 4 rows, or ``{"matrix": …}``;
    rigid (orthonormal rotation, last row 0 0 0 1), metres."""
    p = existing_file(path, "transform JSON")
    try:
        data = json.loads(p.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"{p}: not valid JSON: {err}") from None
    if isinstance(data, dict):
        data = data.get("matrix")
    try:
        t = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{p}: expected a 4×4 matrix of numbers") from None
    if t.shape != (4, 4) or not np.isfinite(t).all():
        raise InputError(f"{p}: expected a finite 4×4 matrix, got shape {t.shape}")
    r = t[:3, :3]
    if not np.allclose(t[3], [0, 0, 0, 1]) or not np.allclose(r.T @ r, np.eye(3), atol=1e-4) \
            or np.linalg.det(r) < 0:
        raise InputError(f"{p}: not a rigid transform (rotation not orthonormal or last row "
                         "not 0 0 0 1)")
    return t


def load_predictor(model_dir: str | Path, n_samples: int | None = None,
                   seed: int = 0) -> "SktPredictor | FlowReadout":
    """The one-SKT predictor in ``model_dir``: an ``skt_flow`` folder (``skt_flow.json``,
    as ``train_baselines`` writes it) gives a :class:`~skt_lib.cli.flow_readout.FlowReadout`
    (``n_samples`` samples, its default where None; noise seeded with ``seed``; its samples
    ordered by the training objects of the data root the folder lies in,
    ``<root>/train_baselines/skt_flow``, where that root holds them, else by the cloud
    check), any other an SCTDN :class:`~skt_lib.learning.predictor.SktPredictor`
    (``train``'s folder)."""
    # PyTorch: only where a model is loaded
    from skt_lib.cli.flow_readout import N_SAMPLES, FlowReadout
    from skt_lib.learning.predictor import SktPredictor

    d = Path(model_dir)
    if not d.is_dir():
        raise InputError(f"{d}: no such model folder (`make repro` trains skt_flow into "
                         "data/train_baselines/skt_flow and SCTDN into data/train)")
    try:
        if (d / "skt_flow.json").is_file():
            return FlowReadout.load(d, N_SAMPLES if n_samples is None else n_samples, seed,
                                    probes=_probes_beside(d))
        if n_samples is not None:
            raise InputError(f"--samples goes with an skt_flow model; {d} holds no "
                             "skt_flow.json")
        return SktPredictor.load(d)
    except DataError as err:
        raise InputError(str(err)) from None


def _probes_beside(model_dir: Path):
    """The training objects of the data root ``model_dir`` was trained in (two folders up)
    as :mod:`skt_lib.eval.probe_check`'s probes; None where that root does not hold them."""
    from skt_lib.eval.probe_check import load_probes

    parents = model_dir.resolve().parents
    root = parents[1] if len(parents) > 1 else None
    if root is None or not all((root / f).is_file() for f in (
            "mesh_gen/objects.parquet", "rotation_extraction/keypoints.parquet")):
        return None
    return load_probes(root)


@contextmanager
def progress(total: int, desc: str) -> Iterator[tqdm]:
    """A progress bar on stderr, shown only on a terminal and when the work takes more than
    a second."""
    with tqdm(total=total, desc=desc, delay=1.0, file=sys.stderr, leave=False, disable=None,
              dynamic_ncols=True) as bar:
        yield bar
