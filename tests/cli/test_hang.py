"""``skt hang``: every ``sim_eval`` method, one real Franka trial each, to the verdict
``sim_eval`` gave the same pair; best-of-N proposals; supports without a ground truth."""

import json
import shutil

import pandas as pd
import pytest
import yaml

from skt_lib.config.sim_eval import METHODS
from skt_lib.sim.execute import REASONS
from tests.cli.conftest import EASY_SUPPORT, OBJECT, STAGES, run_skt


def _hang(capsys, d, params, method, support=EASY_SUPPORT, obj=OBJECT, *extra):
    return run_skt(capsys, "hang", "--support", support, "--object", obj, "--method", method,
                   "--params", params, "--data-root", d, *extra)


def _printed(out: str) -> dict:
    """The printed line's verdict, failure reason, detail, commands and grasp."""
    head, rest = out.strip().split(": ", 1)
    verdict, *fields = rest.split("; ")
    reason, detail = "", ""
    if verdict != "success":
        reason = verdict.removeprefix("failed: ").split(" (", 1)[0]
        detail = verdict.split(" (", 1)[1][:-1] if " (" in verdict else ""
    counts = next(f for f in fields if " commands, grasp " in f)
    done, total = counts.split(" commands")[0].split("/")
    grasp = counts.split("grasp ")[1].split(",")[0]
    return {"success": verdict == "success", "failure_reason": reason, "detail": detail,
            "n_executed": int(done), "n_commands": int(total),
            "grasp": "" if grasp == "–" else grasp, "fields": fields}


def _row(trials: pd.DataFrame, trial_id: str) -> dict:
    r = trials.set_index("trial_id").loc[trial_id]
    return {k: (bool(r[k]) if k == "success" else r[k])
            for k in ("success", "failure_reason", "detail", "n_executed", "n_commands", "grasp")}


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
def test_hang_runs_every_method_as_sim_eval_does(method, capsys, tmp_path, data_root,
                                                 tiny_evaluated):
    """Each method is built as sim_eval builds it (the same view, latents, planner seed), so
    the trial comes out as sim_eval's trial of the pair; methods the tiny sim_eval leaves out
    (sctdn_cp_feature, vatmart_mod) run their trained model to a verdict."""
    params, _, out_eval, _ = tiny_evaluated
    rrd = tmp_path / "hang.rrd"
    rc, out, err = _hang(capsys, data_root, params, method, EASY_SUPPORT, OBJECT, "--rrd", rrd)
    assert rc == 0, err
    got = _printed(out)
    assert got["success"] or got["failure_reason"] in REASONS, out
    assert rrd.stat().st_size > 10_000  # robot meshes and the rollout
    trials = pd.read_parquet(out_eval / "trials.parquet")
    tid = f"{method}/{EASY_SUPPORT}/{OBJECT}"
    if method in set(trials["method"]):
        assert {k: got[k] for k in _row(trials, tid)} == _row(trials, tid), out
    if method in ("oracle", "oracle_floating"):  # the ground truth hangs on an easy support
        assert got["success"], out
    if method in ("vatmart", "vatmart_mod", "skt_flow"):
        assert "proposal 1 of 1" in got["fields"], out
    if method == "omnihang":
        assert any(f.startswith(("planned in", "no plan in")) for f in got["fields"]), out


@pytest.mark.slow
def test_hang_proposals_are_sim_evals_best_of_n(capsys, data_root, tiny_evaluated):
    """--proposals N runs the proposals in order until one hangs: on the pair whose proposals
    sim_eval ran most of, the trial it stops at is sim_eval's last one, verdict and all."""
    params, _, out_eval, _ = tiny_evaluated
    n = yaml.safe_load(params.read_text())["sim_eval"]["n_proposals"]
    trials = pd.read_parquet(out_eval / "trials.parquet")
    v = trials[trials["method"] == "vatmart"]
    runs = v.groupby(["support_id", "object_id"])["proposal"].max()
    support, obj = runs.sort_values(kind="stable").index[-1]
    assert runs.max() >= 1, "no pair ran a second proposal: this test needs one"
    last = v[(v["support_id"] == support) & (v["object_id"] == obj)]["proposal"].max()
    rc, out, err = _hang(capsys, data_root, params, "vatmart", support, obj, "--proposals", n)
    assert rc == 0, err
    got = _printed(out)
    tid = f"vatmart/{support}/{obj}" + (f"/p{last}" if last else "")
    assert {k: got[k] for k in _row(trials, tid)} == _row(trials, tid), out
    assert any(f.startswith(f"proposal {last + 1} of {n}") for f in got["fields"]), out


@pytest.mark.slow
def test_hang_proposals_stop_at_the_first_that_hangs(capsys, monkeypatch, data_root,
                                                     tiny_dataset):
    """The tiny VAT-Mart hangs nothing, so the verdict of the second proposal is forced: the
    run stops there, and the printed line is that trial's."""
    from skt_lib.cli import hang

    ran, real = [], hang.run_trial

    def second_hangs(task):
        out = real(task)
        ran.append(task.trial_id)
        if task.trial_id.endswith("/p1"):
            out["row"] = {**out["row"], "success": True, "failure_reason": "", "detail": ""}
        return out

    monkeypatch.setattr(hang, "run_trial", second_hangs)
    params = tiny_dataset[0]
    rc, out, err = _hang(capsys, data_root, params, "vatmart", EASY_SUPPORT, OBJECT,
                         "--proposals", "3")
    assert rc == 0, err
    stem = f"vatmart/{EASY_SUPPORT}/{OBJECT}"
    assert ran == [stem, f"{stem}/p1"]
    assert _printed(out)["success"] and "proposal 2 of 3" in _printed(out)["fields"], out


@pytest.mark.slow
def test_a_support_without_ground_truth(capsys, tmp_path, data_root, tiny_dataset):
    """An imported support whose record holds no SKT: a learned method hangs on it, a
    privileged one says why it cannot."""
    params, data, _ = tiny_dataset
    root = tmp_path / "data"
    root.mkdir()
    for stage in STAGES:
        (root / stage).symlink_to(data_root / stage, target_is_directory=True)
    d = root / "user" / "supports" / "bare_hook"
    shutil.copytree(data / "mesh_gen" / "supports" / EASY_SUPPORT, d)
    (d / f"{EASY_SUPPORT}.urdf").rename(d / "bare_hook.urdf")
    (d / "support.json").write_text(json.dumps({"name": "bare_hook", "difficulty": "easy"}))

    rc, out, err = _hang(capsys, root, params, "sctdn", "bare_hook")
    assert rc == 0, err
    got = _printed(out)
    assert out.startswith("sctdn bare_hook × ")
    assert got["success"] or got["failure_reason"] in REASONS, out

    rc, out, err = _hang(capsys, root, params, "oracle", "bare_hook")
    assert rc == 2 and out == ""
    assert err.strip() == (f"ERROR: bare_hook: has no ground-truth SKT in {d / 'support.json'} "
                           "(no 'skts'); --method oracle is privileged (built from the ground "
                           "truth) and needs one; the learned methods (template_only, sctdn, "
                           "sctdn_cp_feature, vatmart, vatmart_mod, skt_flow) do not")
