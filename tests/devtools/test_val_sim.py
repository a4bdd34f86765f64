"""tools/val_sim.py: validation supports meet training objects in simulation; nothing of the
test set is used."""

import json

import pandas as pd
import pytest

from tools.val_sim import main


def test_validation_supports_meet_training_objects_only(tiny_evaluated, tmp_path):
    params, data, _, _ = tiny_evaluated
    out = tmp_path / "val_sim.json"
    assert main(["--params", str(params), "--data-root", str(data), "--methods", "sctdn",
                 "template_only", "--model", f"sctdn={data / 'train'}", "--out", str(out)]) == 0
    got = json.loads(out.read_text())
    supports = pd.read_parquet(data / "mesh_gen" / "supports.parquet").set_index("support_id")
    objects = pd.read_parquet(data / "mesh_gen" / "objects.parquet").set_index("object_id")
    pairs = [k.split("/") for k in got["outcomes"]["sctdn"]]
    assert {supports.loc[s, "split"] for s, _ in pairs} == {"val"}
    assert {objects.loc[o, "split"] for _, o in pairs} == {"train"}
    assert not any(objects.loc[o, "is_reference"] for _, o in pairs)
    assert len(pairs) == got["supports"] * got["objects"] > 0
    assert got["outcomes"]["sctdn"].keys() == got["outcomes"]["template_only"].keys()
    rate = sum(got["outcomes"]["sctdn"].values()) / len(pairs)
    assert got["methods"]["sctdn"]["success"]["all"] == pytest.approx(rate)
    c = got["paired"]["sctdn_vs_template_only"]
    assert c["n_pairs"] == len(pairs)


def test_a_model_override_must_name_a_model(capsys):
    with pytest.raises(SystemExit):
        main(["--model", "oracle=/tmp/x"])
    assert "expected NAME=DIR" in capsys.readouterr().err


def test_a_hang_taper_override_keeps_the_weights_and_moves_only_the_deformation(tiny_dataset):
    import numpy as np
    import torch

    from skt_lib.learning.predictor import SktPredictor
    from tools.val_sim import with_readout

    _, data, _ = tiny_dataset
    base = SktPredictor.load(data / "train")
    tapered = with_readout(base, hang_taper=3)
    assert tapered.cfg.hang_taper == 3 and base.cfg.hang_taper == 0
    cloud = np.load(data / "render_views" / sorted(p.name for p in (data / "render_views").iterdir()
                                                    if p.suffix == ".npz")[0])["points"][0]
    a, b = base.predict(cloud), tapered.predict(cloud)
    template = base.predict(cloud, deform=False).positions
    assert not np.allclose(a.positions[0], template[0], rtol=0, atol=1e-6)  # the model deforms
    assert np.allclose(b.positions[0], template[0], rtol=0, atol=1e-9)  # tapered: the hang stays
    assert np.allclose(a.positions[3:], b.positions[3:])  # past the taper: the same path
    # the cloud check's override: the same weights, the read-out picks among its candidates
    checked = with_readout(base, check_families=1)
    assert checked.cfg.check_families == 1 and base.cfg.check_families == 0
    assert all(torch.equal(v, base.model.state_dict()[k])
               for k, v in checked.model.state_dict().items())
    c = checked.predict(cloud).positions
    assert np.allclose(c, a.positions) or np.allclose(c, template)


def test_the_oracles_run_on_validation_and_the_robot_base_moves_the_panda(tiny_evaluated, tmp_path):
    params, data, _, _ = tiny_evaluated
    runs = {}
    for name, base in (("here", []), ("far", ["--robot-base", "5", "0", "0.3"])):
        out = tmp_path / f"{name}.json"
        assert main(["--params", str(params), "--data-root", str(data), "--methods", "oracle",
                     "oracle_floating", *base, "--out", str(out)]) == 0
        runs[name] = json.loads(out.read_text())
    here, far = runs["here"], runs["far"]
    assert far["robot_base_m"] == [5.0, 0.0, 0.3] and here["robot_base_m"] != far["robot_base_m"]
    n = here["supports"] * here["objects"]
    assert n > 0 and len(far["outcomes"]["oracle"]) == n
    # 5 m away the Panda reaches no hang: nothing hangs, and the set-up finds no grasp ...
    assert here["methods"]["oracle"]["success"]["all"] > 0
    assert far["methods"]["oracle"]["success"]["all"] == 0
    ik = {k: r["methods"]["oracle"]["failures_by_reason"]["ik_failed"] for k, r in runs.items()}
    assert ik["far"] > ik["here"]
    # ... and the floating hand, which has no base, is not moved
    assert far["outcomes"]["oracle_floating"] == here["outcomes"]["oracle_floating"]


def test_no_clear_runs_skt_flows_samples_as_drawn(tiny_evaluated, monkeypatch):
    """By default the trials get sim_eval's read-out: sim_eval.flow_samples samples drawn
    from sim_eval.flow_contacts contact hypotheses, moved clear of the cloud
    (skt_lib.eval.clear_shift), ordered by the training objects (skt_lib.eval.probe_check),
    the first n_proposals. --no-probes: n_proposals samples in the cloud check's order;
    with --no-clear unmoved; --flow-contacts 1: from the argmax alone."""
    import numpy as np

    import tools.val_sim as val_sim
    from skt_lib.eval.clear_shift import shifted
    from skt_lib.eval.contact_hypotheses import ContactHypotheses, propose
    from skt_lib.eval.probe_check import load_probes, ordered
    from skt_lib.eval.protocol import load_test_set
    from skt_lib.config.params_file import load_params
    from skt_lib.learning.flow import FlowPredictor
    from skt_lib.seeding import item_rng

    params_path, data, _, _ = tiny_evaluated
    seen = {}

    class Stop(Exception):
        pass

    def capture(methods, supports, objects, positions, *rest):
        seen["positions"] = positions
        raise Stop

    monkeypatch.setattr(val_sim, "run_rounds", capture)
    got = {}
    for flag in ([], ["--no-probes"], ["--no-probes", "--no-clear"],
                 ["--no-probes", "--flow-contacts", "1"]):
        with pytest.raises(Stop):
            main(["--params", str(params_path), "--data-root", str(data), "--methods", "skt_flow",
                  *flag])
        got[" ".join(flag)] = seen["positions"]
    params = load_params(params_path)
    p = params.sim_eval
    supports, _, _ = load_test_set(data, params.clustering.T, params.common.seed,
                                   p.grasp_pitch_deg, p.grasp_rolls_deg, p.grasp_yaws_deg,
                                   support_split="val", object_split="train",
                                   grasp_sphere=p.grasp_sphere_directions)
    flow = FlowPredictor.load(data / "train_baselines" / "skt_flow")
    probes = load_probes(data)
    assert p.flow_samples > p.n_proposals
    differs, reordered = [], []
    for s in supports:
        rng = item_rng(params.common.seed, "val_sim/skt_flow", s.support_id)
        state = rng.bit_generator.state
        raw = propose(flow, s.cloud, rng, p.n_proposals, ContactHypotheses(p.flow_contacts))
        rng.bit_generator.state = state
        own = flow.propose(s.cloud, rng, p.n_proposals)
        key = ("skt_flow", s.support_id)
        drawn, moved = got["--no-probes --no-clear"][key], got["--no-probes"][key]
        argmax = got["--no-probes --flow-contacts 1"][key]
        # the read-out: flow_samples samples, moved, ordered by the training objects, the
        # first n_proposals run
        rng.bit_generator.state = state
        all_moved = [shifted(k, s.cloud) for k in propose(
            flow, s.cloud, rng, p.flow_samples, ContactHypotheses(p.flow_contacts))]
        first = ordered(all_moved, s.cloud, probes)[:p.n_proposals]
        assert len(got[""][key]) == p.n_proposals
        assert all(np.array_equal(a, k.positions) for a, k in zip(got[""][key], first))
        reordered.append(not np.array_equal(first[0].positions, all_moved[0].positions))
        assert all(np.array_equal(a, k.positions) for a, k in zip(drawn, raw))
        assert all(np.array_equal(a, shifted(k, s.cloud).positions) for a, k in zip(moved, raw))
        assert all(np.array_equal(a, shifted(k, s.cloud).positions) for a, k in zip(argmax, own))
        differs.append(not all(np.array_equal(a, b) for a, b in zip(moved, argmax)))
    assert any(differs)  # the hypotheses are not the argmax's samples again
    assert any(reordered)  # the training objects change the cloud check's order


@pytest.mark.parametrize("found", [([], ["object"], []), (["support"], [], [])])
def test_nothing_to_validate_on_is_a_clear_error(monkeypatch, capsys, found):
    from types import SimpleNamespace

    import tools.val_sim as val_sim

    monkeypatch.setattr(val_sim, "load_test_set", lambda *a, **k: found)
    p = SimpleNamespace(grasp_pitch_deg=0, grasp_rolls_deg=(0,), grasp_yaws_deg=(0,),
                        grasp_sphere_directions=0)
    with pytest.raises(SystemExit) as exit_:
        val_sim.validation_set("data-x", 40, 0, p)
    assert exit_.value.code == 2
    assert "data-x: no validation supports with an SKT or no training objects" in \
        capsys.readouterr().err
