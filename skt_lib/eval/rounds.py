"""Running the evaluation's trials: the rounds of proposals, and the replay of chosen
trials with a trace for the recording."""

import dataclasses
from collections.abc import Callable

import pandas as pd

from skt_lib.eval.protocol import make_task
from skt_lib.sim.execute import TrialSettings, TrialTask, run_trial


def run_rounds(methods, supports, objects, positions: dict, settings: TrialSettings,
               run: Callable[[list[TrialTask], str], list[dict]], fallbacks: dict | None = None
               ) -> tuple[list[dict], list[TrialTask]]:
    """Every (method, support, object) trial with each method's first SKT (its set-up may
    fall back on ``fallbacks[method, support_id]``, as
    :func:`~skt_lib.eval.protocol.predict_all` gives them); then, round by round, a proposing
    method's next proposal on the pairs none of its earlier proposals hung (stopping at the
    first success: the best-of-N verdict is the same, the runs fewer).
    ``run(tasks, label)``: :func:`~skt_lib.sim.execute.run_trial` of every task, in order
    (e.g. on a pool). Returns (rows, tasks) in run order."""
    rows, tasks = [], []
    fallbacks = fallbacks or {}
    todo = [make_task(m, s, o, positions[m, s.support_id][0], settings,
                      fallbacks=fallbacks.get((m, s.support_id), ()))
            for m in methods for s in supports for o in objects]
    n_max = max(len(v) for v in positions.values())
    for r in range(n_max):
        if not todo:
            break
        results = run(todo, "trials" if r == 0 else f"proposal {r + 1}")
        rows += [x["row"] for x in results]
        tasks += todo
        by_s, by_o = {s.support_id: s for s in supports}, {o.object_id: o for o in objects}
        todo = [make_task(x["row"]["method"], by_s[x["row"]["support_id"]],
                          by_o[x["row"]["object_id"]], nxt[r + 1], settings, proposal=r + 1)
                for x in results if not x["row"]["success"]
                and len(nxt := positions[x["row"]["method"], x["row"]["support_id"]]) > r + 1]
    return rows, tasks


def pick_rollouts(trials: pd.DataFrame, n: int, methods) -> list[str]:
    """Per method and level: the first success, or else the first failure (so each method
    shows a rollout on every level), then the first trial of each failure reason not shown
    yet; at most ``n`` successes per method. Deterministic (table order)."""
    chosen = []
    for m in methods:
        g = trials[trials["method"] == m]
        ok = g[g["success"]].groupby("difficulty", sort=False).head(1)
        picks = list(ok["trial_id"])[:n]
        shown = set(ok["difficulty"][:n])
        first = g[(g["proposal"] == 0) & ~g["difficulty"].isin(shown)]
        picks += list(first.groupby("difficulty", sort=False).head(1)["trial_id"])
        rest = g[~g["success"] & ~g["trial_id"].isin(picks)]
        seen = set(g.loc[g["trial_id"].isin(picks), "failure_reason"])
        picks += list(rest[~rest["failure_reason"].isin(seen)]
                      .groupby("failure_reason", sort=False).head(1)["trial_id"])
        chosen += picks
    return chosen


def replay(chosen: list[str], tasks: list[TrialTask], rows: list[dict], settings: TrialSettings,
           record_every: int, run: Callable[[list[TrialTask], str], list[dict]] | None = None
           ) -> list[tuple]:
    """Run the ``chosen`` trials again with a trace every ``record_every`` steps: ``[(task,
    {"row", "trace"})]``; ``run(tasks, label)`` as in :func:`run_rounds` (e.g. on a pool;
    default: here, in order). Raises if a replay's row differs from the evaluated one
    (recording must not change what happened)."""
    by_id = {t.trial_id: t for t in tasks}
    rows_by_id = {r["trial_id"]: r for r in rows}
    traced = [dataclasses.replace(by_id[tid], settings=settings, record_every=record_every)
              for tid in chosen]
    results = (run or (lambda ts, _: [run_trial(t) for t in ts]))(traced, "recording")
    out = []
    for tid, result in zip(chosen, results):
        if result["row"] != rows_by_id[tid]:
            raise RuntimeError(f"{tid}: the recorded replay differs from the evaluated trial")
        out.append((by_id[tid], result))
    return out
