"""The measurements behind ``make bench`` (``stages/bench.py``, which says what each key
means): rendering, batch-1 inference of SCTDN and skt_flow, and the executors on the same
sim_eval trials. Not a stage's dependency: nothing here changes an artifact."""

import dataclasses
import time
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS
from skt_lib.eval.clear_shift import shifted
from skt_lib.eval.contact_hypotheses import ContactHypotheses, propose
from skt_lib.eval.methods import load_models, method_for
from skt_lib.eval.probe_check import load_probes, ordered
from skt_lib.eval.protocol import load_test_set, make_task, trial_settings
from skt_lib.io import read_npz, read_table
from skt_lib.learning.flow import FlowPredictor
from skt_lib.learning.predictor import SktPredictor
from skt_lib.perception.views import RENDER_SPEC, RenderTask, render_support
from skt_lib.schemas import SUPPORTS
from skt_lib.sim.execute import EXECUTORS, TrialSettings, run_trial


def render_bench(params, root: Path, per_level: int, tmp: Path) -> dict:
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS)
    chosen = [r for lv in LEVELS
              for r in list(supports[supports["difficulty"] == lv].itertuples())[:per_level]]
    render_ms, total_ms = [], []
    for r in chosen:
        task = RenderTask(r.support_id, str(root / "mesh_gen" / r.mesh_path),
                          str(tmp / f"{r.support_id}.npz"), params.common.seed, params.render_views)
        t0 = time.perf_counter()
        out = render_support(task)
        n_views = len(out["render_s"])
        total_ms.append(1000 * (time.perf_counter() - t0) / n_views)
        render_ms += [1000 * t for t in out["render_s"]]
    return {"render_ms_per_view_median": float(np.median(render_ms)),
            "render_total_ms_per_view_median": float(np.median(total_ms))}


#: Views ``_median_ms`` times, after the untimed warm-up ones.
N_TIMED, N_WARMUP = 100, 10


def _median_ms(root: Path, predict, n: int = N_TIMED, warmup: int = N_WARMUP) -> float:
    """Median wall time (ms) of ``predict(cloud)`` over ``n`` different rendered views after
    ``warmup`` untimed ones (the first ``warmup`` of the same views), one process."""
    clouds = [read_npz(f, RENDER_SPEC)["points"] for f in sorted((root / "render_views").glob("*.npz"))[:5]]
    views = [c[v] for c in clouds for v in range(0, c.shape[0], 2)][:n]
    for cloud in views[:warmup]:
        predict(cloud)
    times = []
    for cloud in views:
        t0 = time.perf_counter()
        predict(cloud)
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times))


def sctdn_bench(root: Path) -> dict:
    """SCTDN inference, batch 1, N points in → SKT out, model loaded."""
    predictor = SktPredictor.load(root / "train")
    return {"sctdn_inference_ms_median": _median_ms(root, predictor.predict)}


#: skt_flow's read-out steps, timed apart by :func:`flow_bench`.
FLOW_STEPS = ("sample", "clear", "order")


def flow_bench(root: Path, n_samples: int, seed: int, n_contacts: int) -> dict:
    """skt_flow inference, batch 1: N points in → ``n_samples`` samples from ``n_contacts``
    contact hypotheses, each moved clear of the points, ordered by the training objects
    carried along them (the first: the one SKT its single-SKT row runs), model and probes
    loaded; and each of the three steps' median apart (:data:`FLOW_STEPS`)."""
    predictor = FlowPredictor.load(root / "train_baselines" / "skt_flow")
    probes = load_probes(root)
    rng, h = np.random.default_rng(seed), ContactHypotheses(n_contacts)
    steps = {k: [] for k in FLOW_STEPS}

    def predict(cloud):
        t0 = time.perf_counter()
        skts = propose(predictor, cloud, rng, n_samples, h)
        t1 = time.perf_counter()
        skts = [shifted(k, cloud) for k in skts]
        t2 = time.perf_counter()
        first = ordered(skts, cloud, probes)[0]
        for k, a, b in zip(FLOW_STEPS, (t0, t1, t2), (t1, t2, time.perf_counter())):
            steps[k].append(1000 * (b - a))
        return first

    out = {"skt_flow_inference_ms_median": _median_ms(root, predict)}
    for k, ms in steps.items():  # the timed views only: the warm-up ones came first
        out[f"skt_flow_{k}_ms_median"] = float(np.median(ms[N_WARMUP:]))
    return out


#: The methods whose SKTs the executor bench runs: the ground truth (mostly hung) and the
#: learned SKT (hung and failed by every reason), so that verdicts of both kinds are compared.
SIM_BENCH_METHODS = ("oracle", "sctdn")


def found_grasp(row: dict) -> bool:
    """Whether a trial's set-up found a grasp (``row``: schema ``trials``): False only for
    ``ik_failed`` with no grasp chosen, a trial that spent its time in the grasp search."""
    return not (row["failure_reason"] == "ik_failed" and not row["grasp"])


def sim_bench(params, root: Path, per_level: int, run_items) -> dict:
    """Every executor of :data:`~skt_lib.sim.execute.EXECUTORS` on the same trials (the SKTs
    of :data:`SIM_BENCH_METHODS` on ``per_level`` test supports per level × every test object),
    one after the other on ``compute.n_workers`` workers by ``run_items`` (the stages'
    runner); each one's verdicts against the reference executor's.

    Trials whose set-up finds no grasp with the default executor (:func:`found_grasp`) are left
    out of all three: they execute nothing, so they time the grasp search alone — every grasp
    candidate on the trial's SKT and each it may fall back to (the oracle: all of the
    support's stored SKTs), which the reference's numpy IK takes over 15 minutes per trial for
    (support_00095: 8 SKTs × 288 grasps) — and
    ``sim_bench_setup_failures_excluded`` counts them."""
    p = params.sim_eval
    supports, objects, _ = load_test_set(root, params.clustering.T, params.common.seed,
                                         p.grasp_pitch_deg, p.grasp_rolls_deg, p.grasp_yaws_deg,
                                         grasp_sphere=p.grasp_sphere_directions)
    chosen = [s for lv in LEVELS for s in [s for s in supports if s.difficulty == lv][:per_level]]
    models = load_models(root, SIM_BENCH_METHODS, params.clustering.T)
    settings = trial_settings(p, params.contact_sim)
    default = TrialSettings.__dataclass_fields__["executor"].default
    tasks = []
    for m in SIM_BENCH_METHODS:
        for s in chosen:
            skt = method_for(m, s.support_id, s.gt, params, models).predict(s.cloud)
            tasks += [make_task(m, s, o, skt.positions, settings,
                                fallbacks=skt.fallbacks[:p.setup_fallbacks]) for o in objects]

    def run(executor: str, trials: list, label: str) -> list[dict]:
        with_executor = dataclasses.replace(settings, executor=executor)
        return run_items(run_trial, [dataclasses.replace(t, settings=with_executor) for t in trials],
                         params.compute, label)[0]

    screen = {r["row"]["trial_id"] for r in run(default, tasks, "bench sim, set-up screen")
              if found_grasp(r["row"])}
    kept = [t for t in tasks if t.trial_id in screen]
    verdicts, rates = {}, {}
    for executor in EXECUTORS:
        t0 = time.perf_counter()
        results = run(executor, kept, f"bench sim, {executor}")
        rates[executor] = 60.0 * len(kept) / (time.perf_counter() - t0)
        verdicts[executor] = [(r["row"]["trial_id"], r["row"]["failure_reason"] or "success")
                              for r in results]
    previous = EXECUTORS[EXECUTORS.index(default) - 1]
    ref = verdicts["reference"]
    out = {"sim_bench_trials": len(kept), "sim_bench_executor": default,
           "sim_bench_setup_failures_excluded": len(tasks) - len(kept),
           "sim_bench_failures_reference": sum(v != "success" for _, v in ref),
           "sim_trials_per_min": rates[default],
           "sim_trials_per_min_previous": rates[previous],
           "sim_trials_per_min_reference": rates["reference"],
           "sim_speedup_vs_previous_executor": rates[default] / rates[previous],
           "sim_speedup_vs_reference_executor": rates[default] / rates["reference"]}
    for name, executor in (("", default), ("_previous", previous)):
        differ = [f"{tid}: {a} → {b}" for (tid, a), (_, b) in zip(ref, verdicts[executor])
                  if a != b]
        out[f"sim_verdict_agreement{name}"] = 1.0 - len(differ) / len(ref)
        out[f"sim_success_agreement{name}"] = 1.0 - sum(
            (a == "success") != (b == "success")
            for (_, a), (_, b) in zip(ref, verdicts[executor])) / len(ref)
        out[f"sim_verdict_disagreements{name}"] = differ
    return out
