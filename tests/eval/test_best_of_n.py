"""Best-of-N accounting (the paper's VAT-Mart count) and the proposal rounds of sim_eval."""

import numpy as np
import pandas as pd

from skt_lib.eval import protocol
from skt_lib.eval.protocol import SINGLE, per_pair
from skt_lib.eval.rounds import run_rounds
from skt_lib.sim.grasp import Grasp


def _row(method, support, obj, proposal, success, reason=""):
    return {"trial_id": f"{method}/{support}/{obj}/p{proposal}", "method": method,
            "support_id": support, "object_id": obj, "difficulty": "easy", "category": "mug",
            "success": success, "failure_reason": "" if success else reason, "proposal": proposal}


def test_per_pair_counts_any_proposal_and_keeps_the_first_alone():
    trials = pd.DataFrame([
        _row("sctdn", "s1", "o1", 0, True), _row("sctdn", "s1", "o2", 0, False, "dropped"),
        _row("vatmart", "s1", "o1", 0, False, "ik_failed"), _row("vatmart", "s1", "o1", 1, True),
        _row("vatmart", "s1", "o2", 0, True),
        _row("vatmart", "s2", "o1", 0, False, "dropped"),
        _row("vatmart", "s2", "o1", 1, False, "perched"),
        _row("vatmart", "s2", "o1", 2, False, "ik_failed"),
    ])
    pairs = per_pair(trials)
    got = {(r.method, r.support_id, r.object_id): (r.success, r.failure_reason)
           for r in pairs.itertuples()}
    assert got == {
        ("sctdn", "s1", "o1"): (True, ""), ("sctdn", "s1", "o2"): (False, "dropped"),
        ("vatmart", "s1", "o1"): (True, ""), ("vatmart", "s1", "o2"): (True, ""),
        ("vatmart", "s2", "o1"): (False, "dropped"),  # proposal 0's reason when none hung
        ("vatmart" + SINGLE, "s1", "o1"): (False, "ik_failed"),
        ("vatmart" + SINGLE, "s1", "o2"): (True, ""),
        ("vatmart" + SINGLE, "s2", "o1"): (False, "dropped"),
    }
    # without proposals the table passes through: one row per trial
    plain = trials[trials["method"] == "sctdn"]
    assert per_pair(plain).equals(plain.reset_index(drop=True))


def _fake_trial(task):
    """Hangs the object iff the SKT's first x coordinate is positive."""
    ok = task.positions[0][0] > 0
    return {"row": {"trial_id": task.trial_id, "method": task.method,
                    "support_id": task.support_id, "object_id": task.object_id, **task.extra,
                    "success": bool(ok), "failure_reason": "" if ok else "dropped"}, "trace": []}


def test_rounds_stop_at_the_first_hung_proposal_and_pass_on_fallbacks():
    grasp = (Grasp("g", tuple(np.eye(4).ravel())),)
    sup = [protocol.TestSupport(f"s{i}", "easy", "hook", "u", "m", np.zeros((4, 3)),
                                np.zeros((10, 3)), 0) for i in range(2)]
    objs = [protocol.TestObject(f"o{j}", "mug", "u", "m", np.eye(4), grasp, 0.1) for j in range(2)]
    skt = lambda x: np.full((4, 3), x)  # noqa: E731
    positions = {("sctdn", "s0"): [skt(-1)], ("sctdn", "s1"): [skt(1)],
                 ("vatmart", "s0"): [skt(-1), skt(-1), skt(1), skt(1)],
                 ("vatmart", "s1"): [skt(-1), skt(-1), skt(-1), skt(-1)]}
    fallbacks = {("sctdn", "s0"): (skt(2), skt(3)), ("sctdn", "s1"): ()}
    rows, tasks = run_rounds(["sctdn", "vatmart"], sup, objs, positions, None,
                             lambda tasks, label: [_fake_trial(t) for t in tasks], fallbacks)
    runs = {}
    for r in rows:
        runs.setdefault((r["method"], r["support_id"], r["object_id"]), []).append(
            (r["proposal"], r["success"]))
    for o in ("o0", "o1"):
        assert runs["sctdn", "s0", o] == [(0, False)]  # one SKT: no second round
        assert runs["vatmart", "s0", o] == [(0, False), (1, False), (2, True)]
        assert runs["vatmart", "s1", o] == [(k, False) for k in range(4)]
    assert [t.trial_id for t in tasks] == [r["trial_id"] for r in rows]
    assert tasks[-1].trial_id.endswith("/p3")
    # a method's fallbacks reach its set-up, for that support only, unswept; proposals have none
    for t in tasks:
        mine = (t.method, t.support_id) == ("sctdn", "s0")
        want = [skt(2), skt(3)] if mine else np.zeros((0, 4, 3))
        assert np.array_equal(np.asarray(t.alternatives).reshape(-1, 4, 3), want), t.trial_id
        assert not t.sweep_alternatives
