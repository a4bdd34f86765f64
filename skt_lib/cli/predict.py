"""``skt predict CLOUD``: the SKT of a user's partial cloud of a supporting item.

The model is SCTDN (``train``'s folder) or ``skt_flow`` (``train_baselines``' folder: its
samples moved clear of the cloud and ordered by the training objects carried along them,
the first one; :mod:`skt_lib.cli.flow_readout`), told apart by the folder's config file.

The cloud is scaled to metres (``--units``), moved into the support frame (``--frame``, or
``--camera``: the frame found from the wall in view, :mod:`skt_lib.perception.wall_frame`),
cleaned (:func:`skt_lib.perception.pointcloud.clean_cloud`), brought to the model's N points
by the same farthest-point sampling and shuffle as every training view
(:func:`skt_lib.perception.pointcloud.sample_to`) and predicted; the SKT is written as JSON
(schema ``skt``, key by key in docs/cli.md, "``skt.json``").
"""

import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from skt_lib.cli.cloud_checks import check_support_cloud
from skt_lib.cli.common import UNITS, count_arg, load_predictor, progress, read_cloud, read_frame
from skt_lib.cli.flow_readout import N_SAMPLES, FlowReadout
from skt_lib.errors import InputError
from skt_lib.geometry.se3 import invert, matrix_to_quat, transform_points
from skt_lib.io import write_json_atomic
from skt_lib.learning.predictor import Skt, SktPredictor
from skt_lib.perception.pointcloud import clean_cloud, median_radius, sample_to
from skt_lib.perception.wall_frame import support_frame

SCHEMA, SCHEMA_VERSION = "skt", 3
#: A cloud said to be in millimetres whose median radius is below this (m) was in metres.
MIN_MEDIAN_RADIUS_M = 0.002
#: ... and, with --camera, whose median range from the camera is below this (m).
MIN_MEDIAN_RANGE_M = 0.02

#: The default model: skt_flow, the best one-SKT method on validation (docs/cli.md says by how
#: much); ``--model data/train`` runs SCTDN, the paper's.
DEFAULT_MODEL = "data/train_baselines/skt_flow"

EXAMPLE = """example:
  skt predict hook.ply -o skt.json --rrd skt.rrd           # skt_flow, the default model
  skt predict hook.ply --model data/train -o sctdn.json    # SCTDN, the paper's network
  skt predict scan.npy --units mm --frame cam_to_support.json
  skt predict raw_depth.ply --camera --up 0 -1 0     # camera frame, wall in view"""


@dataclass(frozen=True, eq=False)
class Prediction:
    skt: Skt | None  # None: the cloud made ready, not predicted yet (model_cloud)
    points: np.ndarray  # (N, 3) the cloud the model saw, support frame, metres
    counts: dict  # cleaning: points in and removed per step
    warnings: tuple[str, ...] = ()  # the frame or the cloud may be off (wall_frame, cloud_checks)
    camera_to_support: np.ndarray | None = None  # (4, 4) the frame --camera found


def prepare_cloud(points: np.ndarray, n: int, units: str = "m", frame: np.ndarray | None = None,
                  seed: int = 0, name: str = "points") -> tuple[np.ndarray, dict, list[str]]:
    """A raw cloud ``(K, 3)`` in ``units`` (camera frame when ``frame`` is the 4×4
    camera-to-support transform, else support frame) → ``(n, 3)`` support frame, metres,
    cleaned and sampled as the model's training views were; the cleaning counts; and the
    warnings of :func:`~skt_lib.cli.cloud_checks.check_support_cloud`, which refuses
    (:class:`InputError`) a cloud with no structure off the wall."""
    a = np.asarray(points, dtype=np.float64) * UNITS[units]
    if frame is not None:
        a = transform_points(frame, a)
    try:
        cleaned = clean_cloud(a, name=name)
    except ValueError as err:
        raise InputError(str(err)) from None
    if units == "mm" and median_radius(cleaned.points) < MIN_MEDIAN_RADIUS_M:
        raise InputError(f"{name}: median radius {median_radius(cleaned.points) * 1000:.3g} mm "
                         "after conversion from millimetres — was it in metres already? "
                         "(drop --units mm)")
    warnings = check_support_cloud(cleaned.points, name)
    rng = np.random.default_rng(seed)
    return sample_to(cleaned.points, n, rng), {**cleaned.counts, "n_points": n}, warnings


def model_cloud(cfg, points: np.ndarray, units: str = "m", frame: np.ndarray | None = None,
                seed: int = 0, name: str = "points") -> Prediction:
    """:func:`prepare_cloud` for a model of config ``cfg`` (its ``n_points``; refused, as
    :class:`InputError`, below the ``centres[0]`` distinct points its first farthest-point
    sample needs): a :class:`Prediction` without its ``skt`` yet (None)."""
    cloud, counts, warnings = prepare_cloud(points, cfg.n_points, units, frame, seed, name)
    distinct, need = len(np.unique(cloud, axis=0)), cfg.centres[0]
    if distinct < need:
        raise InputError(f"{name}: {distinct} distinct points left on the structure after "
                         f"cleaning, the model needs at least {need}")
    return Prediction(None, cloud, counts, tuple(warnings))


def camera_cloud(cfg, points: np.ndarray, up: np.ndarray | None, units: str = "m",
                 seed: int = 0, name: str = "points") -> Prediction:
    """A raw camera-frame cloud with the wall in view: the support frame found from it
    (:func:`~skt_lib.perception.wall_frame.support_frame`; ``up`` in the camera frame, or
    ``None`` for a level camera), the wall removed, then as :func:`model_cloud` (``skt`` None,
    ``camera_to_support`` set)."""
    a = np.asarray(points, dtype=np.float64) * UNITS[units]
    finite = a[np.isfinite(a).all(axis=1)]
    if units == "mm" and len(finite):
        range_m = float(np.median(np.linalg.norm(finite, axis=1)))
        if range_m < MIN_MEDIAN_RANGE_M:
            raise InputError(f"{name}: median range {range_m * 1000:.3g} mm after conversion from "
                             "millimetres — was it in metres already? (drop --units mm)")
    wf = support_frame(a, up, name=name)
    ready = model_cloud(cfg, wf.points, "m", None, seed, name)
    return Prediction(None, ready.points, {**ready.counts, "n_wall": wf.n_wall},
                      wf.warnings + ready.warnings, wf.camera_to_support)


def predict_cloud(predictor: SktPredictor | FlowReadout, points: np.ndarray, units: str = "m",
                  frame: np.ndarray | None = None, seed: int = 0, name: str = "points"
                  ) -> Prediction:
    ready = model_cloud(predictor.cfg, points, units, frame, seed, name)
    return replace(ready, skt=predictor.predict(ready.points))


def predict_camera(predictor: SktPredictor | FlowReadout, points: np.ndarray,
                   up: np.ndarray | None, units: str = "m", seed: int = 0,
                   name: str = "points") -> Prediction:
    """:func:`camera_cloud`, then the model's SKT of it."""
    ready = camera_cloud(predictor.cfg, points, up, units, seed, name)
    return replace(ready, skt=predictor.predict(ready.points))


def _waypoints(frames: np.ndarray) -> list[dict]:
    return [{"position": f[:3, 3].tolist(), "quat": matrix_to_quat(f[:3, :3]).tolist()}
            for f in frames]


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def model_kind(predictor) -> str:
    return "skt_flow" if isinstance(predictor, FlowReadout) else "sctdn"


def skt_record(pred: Prediction, source: str, model: str, kind: str = "sctdn") -> dict:
    """The JSON document of docs/cli.md (schema ``skt`` v3; ``camera`` only with --camera).
    ``kind``: the model's, ``sctdn`` or ``skt_flow`` (no families: ``family`` and its
    probability are null)."""
    skt = pred.skt
    record = {
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
        "frame": "support", "units": "m", "quaternion_order": "xyzw",
        "source": source, "model": model, "model_kind": kind,
        "T": len(skt.positions),
        "waypoints": _waypoints(skt.frames),
        "family": skt.family if skt.family >= 0 else None,
        "contact_point": np.asarray(skt.contact).tolist(),
        "points": pred.points.tolist(),
        "affordance": np.asarray(skt.affordance, dtype=np.float64).tolist(),
        "cleaning": pred.counts,
        "confidence": {  # a controller may decline an SKT below its own thresholds
            "family_probability": _finite_or_none(skt.family_probability),
            "affordance_peak": float(np.max(skt.affordance)),
        },
        "warnings": list(pred.warnings),
    }
    if pred.camera_to_support is not None:  # the SKT again in the camera frame
        to_cam = invert(pred.camera_to_support)
        record["camera"] = {
            "camera_to_support": pred.camera_to_support.tolist(),
            "waypoints": _waypoints(to_cam @ skt.frames),
            "contact_point": transform_points(to_cam, np.asarray(skt.contact)[None])[0].tolist(),
        }
    return record


def median_predict_ms(model_dir: str | Path, cloud: np.ndarray, n: int = 30, warmup: int = 3
                      ) -> float:
    """Median wall time (ms) of ``skt predict``'s prediction itself — cleaning, sampling and
    the network, model already loaded (process start and loading excluded) — on one cloud."""
    predictor = load_predictor(model_dir)
    for _ in range(warmup):
        predict_cloud(predictor, cloud)
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        predict_cloud(predictor, cloud)
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times))


def add_parser(sub) -> None:
    ap = sub.add_parser("predict", help="predict the SKT of a partial point cloud of a hook",
                        description=__doc__.splitlines()[0], epilog=EXAMPLE)
    ap.add_argument("cloud", help="point cloud: .ply .pcd .npy .npz .xyz .txt (N×3)")
    ap.add_argument("--model", default=DEFAULT_MODEL,
                    help=f"trained model folder: skt_flow's (train_baselines/skt_flow) or "
                         f"SCTDN's (train) (default: {DEFAULT_MODEL})")
    ap.add_argument("--frame", help="JSON 4×4 camera-to-support transform (metres); "
                                    "without it the cloud is taken to be in the support frame")
    ap.add_argument("--camera", action="store_true",
                    help="the cloud is a raw camera-frame cloud with the wall in view: find the "
                         "support frame from the wall (needs --up or --level)")
    ap.add_argument("--up", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="with --camera: the up direction (against gravity) in the camera frame")
    ap.add_argument("--level", action="store_true",
                    help="with --camera: the camera is held level (image rows horizontal)")
    ap.add_argument("--units", choices=sorted(UNITS), default="m", help="units of the cloud")
    ap.add_argument("-o", "--output", default="skt.json", help="SKT JSON to write (default: skt.json)")
    ap.add_argument("--rrd", help="also write a Rerun recording: cloud, affordance, SKT, and "
                                   "SCTDN's template or skt_flow's other samples")
    ap.add_argument("--seed", type=int, default=0,
                    help="seed of the sampling to N points (and of skt_flow's noise)")
    ap.add_argument("--samples", type=count_arg, metavar="N",
                    help=f"skt_flow models only: samples drawn, each moved clear of the cloud; "
                         f"the first by the training objects carried along them is the SKT "
                         f"(default {N_SAMPLES}, as Table I's skt_flow row)")
    ap.set_defaults(run=run)


def _references(predictor, pred: Prediction) -> dict[str, np.ndarray]:
    """What the recording shows beside the SKT: SCTDN's family template, aligned at the
    contact; skt_flow's other samples, in the read-out's order."""
    if isinstance(predictor, FlowReadout):
        return {f"samples/{i}": p for i, p in enumerate(pred.skt.fallbacks, start=1)}
    return {"template": predictor.predict(pred.points, deform=False).positions}


def _camera_args(args) -> None:
    if args.camera and args.frame:
        raise InputError("--camera finds the frame from the wall: drop --frame")
    if args.camera and (args.up is None) == (not args.level):
        raise InputError("--camera needs exactly one of --up X Y Z (camera frame) or --level")
    if not args.camera and (args.up is not None or args.level):
        raise InputError("--up and --level go with --camera")


def run(args) -> int:
    _camera_args(args)
    with progress(4, "predict") as bar:
        points = read_cloud(args.cloud)
        frame = read_frame(args.frame) if args.frame else None
        bar.update()
        predictor = load_predictor(args.model, args.samples, args.seed)
        bar.update()
        if args.camera:
            up = None if args.level else np.asarray(args.up, float)
            pred = predict_camera(predictor, points, up, args.units, args.seed, args.cloud)
        else:
            pred = predict_cloud(predictor, points, args.units, frame, args.seed, args.cloud)
        kind = model_kind(predictor)
        bar.update()
        record = skt_record(pred, str(args.cloud), str(args.model), kind)
        if args.rrd:
            from skt_lib.cli.rrd import log_prediction

            log_prediction(Path(args.rrd), pred, _references(predictor, pred))
        write_json_atomic(args.output, record)
        bar.update()
    for w in pred.warnings:
        print(f"warning: {w}", file=sys.stderr)
    c = np.round(pred.skt.contact, 4).tolist()
    chosen = (f"family {pred.skt.family} (probability {pred.skt.family_probability:.2f})"
              if kind == "sctdn" else
              f"the first of {predictor.n_samples} skt_flow samples, moved clear of the cloud, "
              + ("by the training objects carried along them" if predictor.probes is not None
                 else "by the cloud check (no training objects beside the model)"))
    print(f"{args.output}: SKT of {record['T']} waypoints, {chosen}, contact {c} m "
          f"(cleaning kept {len(pred.points)} of {pred.counts['n_in']} points: "
          f"{pred.counts['non_finite']} non-finite, {pred.counts['outliers']} outliers, "
          f"{pred.counts['off_cluster']} off the structure); affordance peak "
          f"{np.max(pred.skt.affordance):.2f}")
    if pred.camera_to_support is not None:
        origin = invert(pred.camera_to_support)[:3, 3].round(4).tolist()
        print(f"support frame from the wall: origin {origin} m in the camera frame "
              f"({pred.counts['n_wall']} wall points removed)")
    return 0
