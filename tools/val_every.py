"""Every proposal on validation (after ``make repro``): each of a proposing method's
``sim_eval.n_proposals`` SKTs of a validation support (skt_flow: each of its
``sim_eval.flow_samples`` samples) hung with every training object (the pairs of
``tools/val_sim.py``), so that rules for *which* SKT to run can be scored offline on the
same trials, and the best of N told from what a pick could reach.

The rules (:data:`RULES`; each sees only the support's cloud and its proposals, never an
outcome): ``first`` (what the method runs: skt_flow's first by the training objects carried
along its samples, :mod:`skt_lib.eval.probe_check`), ``cloud_check`` (skt_flow's first of
the same samples by the cloud check, its read-out before the probes),
``least_penetration`` (the least :func:`~skt_lib.learning.cloud_check.ring_penetrations`
of the SKTs run, the first of equals), ``least_moved`` (the one the move clear of the cloud
shifted least; only with the move), ``medoid`` (the least mean distance to the others,
waypoint by waypoint). On validation the objects hung are the training objects, the probes
themselves, so ``first`` there lets each object judge its own trial; ``probes_held_out`` is
the estimate for objects the probes do not hold: each object's pick by the probes of the
other categories only.
Beside them, bounds no rule can pass: ``random`` (a proposal drawn at random: the mean over
the N) and ``best_of_n`` (any of the N hung).

Writes a JSON (``--out``): per rule and bound the success per level; per rule against
``first`` the pairs gained and lost, the supports up and down, and the support-bootstrap
95 % interval of the difference (:func:`~skt_lib.stats.paired_support_interval`); each
rule's picks, each support's penetrations, and every pair's N outcomes (``outcomes``:
``{"<support_id>/<object_id>": [bool, …]}``). Nothing under the data root or ``reports/``
changes. Costs N × ``tools/val_sim.py``'s first trials of one method (skt_flow on the
default data: 10 samples, 4,000 trials, 11 minutes on 2 idle cores; 30, three times that).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.eval.clear_shift import shifted
from skt_lib.eval.methods import PROPOSING, Proposals, load_models, make_method
from skt_lib.eval.probe_check import load_probes, probe_penetrations, probe_scores
from skt_lib.eval.protocol import make_task, trial_settings
from skt_lib.io import write_json_atomic
from skt_lib.learning.cloud_check import ring_penetrations
from skt_lib.seeding import item_rng
from skt_lib.stats import paired_support_interval
from tools.val_sim import run_all, validation_set

RULES = ("first", "least_penetration", "least_moved", "medoid")
#: skt_flow's rules beside them (module docstring).
PROBE_RULES = ("cloud_check", "probes_held_out")


def picks(drawn: list[np.ndarray], run: list[np.ndarray], cloud: np.ndarray,
          moved: bool) -> tuple[dict[str, int], np.ndarray]:
    """Which proposal each rule of :data:`RULES` runs, from the proposals as drawn and as
    run (``(T, 3)`` each, the same order) and the support's ``cloud (N, 3)``;
    ``least_moved`` only where the method moves its proposals (``moved``: on every support,
    those the move left where they were included). Also each run proposal's
    :func:`~skt_lib.learning.cloud_check.ring_penetrations` (m²)."""
    if not run or len(drawn) != len(run):
        raise ValueError(f"drawn, run: need the same proposals, got {len(drawn)} and {len(run)}")
    pen = ring_penetrations(run, cloud)
    stack = np.stack(run)
    spread = np.linalg.norm(stack[:, None] - stack[None], axis=-1).mean(-1).sum(1)
    out = {"first": 0, "least_penetration": int(np.argmin(pen)), "medoid": int(np.argmin(spread))}
    if moved:
        shifts = [np.linalg.norm(r[0] - d[0]) for d, r in zip(drawn, run)]
        out["least_moved"] = int(np.argmin(shifts))
    return out, pen


def score(outcomes: dict[tuple[str, str], list[bool]], levels: dict[str, str],
          chosen: dict[str, dict[str, int]], rng: np.random.Generator) -> dict:
    """Success per level of every rule (``chosen[rule][support_id]``: the proposal it runs,
    or ``{object_id: proposal}`` where the pick is the object's) and bound, from
    ``outcomes[(support_id, object_id)]`` (one flag per proposal), and each rule against
    ``first`` on the same pairs."""
    keys = list(outcomes)
    groups = np.array([s for s, _ in keys])
    level = np.array([levels[s] for s in groups])
    flags = np.array([outcomes[k] for k in keys], bool)

    def by_level(values: np.ndarray) -> dict[str, float | None]:
        out = {"all": float(values.mean())}
        for lv in LEVELS:
            out[lv] = float(values[level == lv].mean()) if (level == lv).any() else None
        return out

    def picked(pick, s: str, o: str) -> int:
        return pick[s][o] if isinstance(pick[s], dict) else pick[s]

    values = {rule: flags[np.arange(len(keys)), [picked(pick, s, o) for s, o in keys]]
              for rule, pick in chosen.items()}
    out = {name: {"success": by_level(v.astype(float))} for name, v in values.items()}
    out["random"] = {"success": by_level(flags.mean(1))}
    out["best_of_n"] = {"success": by_level(flags.any(1).astype(float))}
    first = values["first"]
    for rule, v in values.items():
        if rule == "first":
            continue
        per = {s: (v[groups == s].mean(), first[groups == s].mean()) for s in dict.fromkeys(groups)}
        ci = paired_support_interval(v, first, groups, rng)
        out[rule]["vs_first"] = {"gained": int((v & ~first).sum()), "lost": int((first & ~v).sum()),
                                 "supports_up": int(sum(a > b for a, b in per.values())),
                                 "supports_down": int(sum(a < b for a, b in per.values())),
                                 "difference_ci95": None if ci is None else list(ci)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/val_every.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--method", default="skt_flow", choices=PROPOSING)
    ap.add_argument("--no-clear", action="store_true",
                    help="skt_flow's samples as drawn, not moved clear of the cloud")
    ap.add_argument("--out", default=Path("data/val_sim/every.json"), type=Path)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    p, T, seed = params.sim_eval, params.clustering.T, params.common.seed
    supports, objects, missing = validation_set(args.data_root, T, seed, p)
    model = load_models(args.data_root, [args.method], T).get(args.method)
    pre = np.asarray(p.kpam_pre_hang_m, float)
    probes = load_probes(args.data_root) if args.method == "skt_flow" else None
    category = {o.object_id: o.category for o in objects}
    settings = trial_settings(p, params.contact_sim)
    chosen = {r: {} for r in (*RULES, *(PROBE_RULES if probes else ()))}
    n = p.flow_samples if probes is not None else p.n_proposals
    pens, tasks = {}, []
    for s in supports:
        # val_sim's generator: its first proposal and best of N are the same SKTs as here
        method = make_method(args.method, model, s.gt, pre, p.kpam_lift_m,
                             rng=item_rng(seed, f"val_sim/{args.method}", s.support_id),
                             n_proposals=n, flow_contacts=p.flow_contacts)
        assert isinstance(method, Proposals)
        move = method.clear and not args.no_clear
        method.clear = False  # the samples as drawn; moved here, so that both are at hand
        skts = method.propose(s.cloud)  # the cloud check's order
        drawn = [k.positions for k in skts]
        run = [shifted(k, s.cloud).positions for k in skts] if move else drawn
        if probes is not None:  # the read-out's order, as val_sim runs it
            pen_o = probe_penetrations(run, s.cloud, probes)
            order = np.argsort(probe_scores(pen_o), kind="stable")
            drawn, run, pen_o = [drawn[i] for i in order], [run[i] for i in order], pen_o[order]
            chosen["cloud_check"][s.support_id] = int(np.flatnonzero(order == 0)[0])
            chosen["probes_held_out"][s.support_id] = {
                o.object_id: int(np.argmin(probe_scores(pen_o[:, [
                    category.get(n) != o.category for n in probes.names]])))
                for o in objects}
        picked, pen = picks(drawn, run, s.cloud, move)
        for rule, i in picked.items():
            chosen[rule][s.support_id] = i
        pens[s.support_id] = (pen * 1e6).tolist()
        tasks += [make_task(args.method, s, o, x, settings, proposal=i)
                  for o in objects for i, x in enumerate(run)]
    chosen = {r: c for r, c in chosen.items() if c}  # least_moved: only with the move
    rows = [x["row"] for x in run_all(tasks, params.compute, f"every proposal of {args.method}")]
    outcomes = {(s.support_id, o.object_id): [False] * n
                for s in supports for o in objects}
    for row in rows:
        outcomes[row["support_id"], row["object_id"]][row["proposal"]] = bool(row["success"])
    levels = {s.support_id: s.difficulty for s in supports}
    table = score(outcomes, levels, chosen, np.random.default_rng(seed))
    out = {"method": args.method, "n_proposals": n, "supports": len(supports),
           "supports_without_skt": missing, "objects": len(objects),
           "moved_clear": move, "rules": table, "picks": chosen,
           "penetration_mm2": pens,
           "outcomes": {f"{s}/{o}": v for (s, o), v in outcomes.items()}}
    write_json_atomic(args.out, out)
    for name, v in table.items():
        line = "  ".join(f"{k} {100 * x:.1f}" for k, x in v["success"].items() if x is not None)
        if "vs_first" in v:
            c = v["vs_first"]
            line += (f"   vs first: +{c['gained']} / −{c['lost']} pairs, supports "
                     f"{c['supports_up']} up / {c['supports_down']} down")
        print(f"{name:>18}: {line}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
