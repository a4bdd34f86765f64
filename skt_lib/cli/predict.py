"""``skt predict CLOUD``: the SKT of a user's partial cloud of a supporting item.

The cloud is scaled to metres (``--units``), moved into the support frame (``--frame``),
cleaned (:func:`skt_lib.perception.pointcloud.clean_cloud`), brought to the model's N points
by the same farthest-point sampling and shuffle as every training view
(:func:`skt_lib.perception.pointcloud.sample_to`) and predicted; the SKT is written as JSON
(schema in README, "Command line").
"""

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.cli.cloud_checks import check_support_cloud
from skt_lib.cli.common import UNITS, load_predictor, progress, read_cloud, read_frame
from skt_lib.errors import InputError
from skt_lib.geometry.se3 import matrix_to_quat, transform_points
from skt_lib.io import write_json_atomic
from skt_lib.learning.predictor import Skt, SktPredictor
from skt_lib.perception.pointcloud import clean_cloud, median_radius, sample_to

SCHEMA, SCHEMA_VERSION = "skt", 2
#: A cloud said to be in millimetres whose median radius is below this (m) was in metres.
MIN_MEDIAN_RADIUS_M = 0.002

EXAMPLE = """example:
  skt predict hook.ply --model data/train -o skt.json --rrd skt.rrd
  skt predict scan.npy --units mm --frame cam_to_support.json"""


@dataclass(frozen=True, eq=False)
class Prediction:
    skt: Skt
    points: np.ndarray  # (N, 3) the cloud the model saw, support frame, metres
    counts: dict  # cleaning: points in and removed per step
    warnings: tuple[str, ...] = ()  # the cloud does not look like a training view (cloud_checks)


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


def predict_cloud(predictor: SktPredictor, points: np.ndarray, units: str = "m",
                  frame: np.ndarray | None = None, seed: int = 0, name: str = "points"
                  ) -> Prediction:
    cloud, counts, warnings = prepare_cloud(points, predictor.cfg.n_points, units, frame, seed,
                                            name)
    return Prediction(predictor.predict(cloud), cloud, counts, tuple(warnings))


def skt_record(pred: Prediction, source: str, model: str) -> dict:
    """The JSON document of README "Command line" (schema ``skt`` v1)."""
    skt = pred.skt
    return {
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
        "frame": "support", "units": "m", "quaternion_order": "xyzw",
        "source": source, "model": model,
        "T": len(skt.positions),
        "waypoints": [{"position": f[:3, 3].tolist(), "quat": matrix_to_quat(f[:3, :3]).tolist()}
                      for f in skt.frames],
        "family": skt.family,
        "contact_point": np.asarray(skt.contact).tolist(),
        "points": pred.points.tolist(),
        "affordance": np.asarray(skt.affordance, dtype=np.float64).tolist(),
        "cleaning": pred.counts,
        "confidence": {  # a controller may decline an SKT below its own thresholds
            "family_probability": skt.family_probability,
            "affordance_peak": float(np.max(skt.affordance)),
        },
        "warnings": list(pred.warnings),
    }


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
    ap.add_argument("--model", default="data/train", help="trained model folder (default: data/train)")
    ap.add_argument("--frame", help="JSON 4×4 camera-to-support transform (metres); "
                                    "without it the cloud is taken to be in the support frame")
    ap.add_argument("--units", choices=sorted(UNITS), default="m", help="units of the cloud")
    ap.add_argument("-o", "--output", default="skt.json", help="SKT JSON to write (default: skt.json)")
    ap.add_argument("--rrd", help="also write a Rerun recording: cloud, affordance, template, SKT")
    ap.add_argument("--seed", type=int, default=0, help="seed of the sampling to N points")
    ap.set_defaults(run=run)


def run(args) -> int:
    with progress(4, "predict") as bar:
        points = read_cloud(args.cloud)
        frame = read_frame(args.frame) if args.frame else None
        bar.update()
        predictor = load_predictor(args.model)
        bar.update()
        pred = predict_cloud(predictor, points, args.units, frame, args.seed, args.cloud)
        template = predictor.predict(pred.points, deform=False)
        bar.update()
        record = skt_record(pred, str(args.cloud), str(args.model))
        if args.rrd:
            from skt_lib.cli.rrd import log_prediction

            log_prediction(Path(args.rrd), pred, template.positions)
        write_json_atomic(args.output, record)
        bar.update()
    for w in pred.warnings:
        print(f"warning: {w}", file=sys.stderr)
    c = np.round(pred.skt.contact, 4).tolist()
    print(f"{args.output}: SKT of {record['T']} waypoints, family {pred.skt.family}, contact {c} m "
          f"(cleaning kept {len(pred.points)} of {pred.counts['n_in']} points: "
          f"{pred.counts['non_finite']} non-finite, {pred.counts['outliers']} outliers, "
          f"{pred.counts['off_cluster']} off the structure); family probability "
          f"{pred.skt.family_probability:.2f}, affordance peak {np.max(pred.skt.affordance):.2f}")
    return 0
