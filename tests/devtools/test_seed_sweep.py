"""tools/seed_sweep.py: a seed's scratch outputs are reused only for the inputs they were made
from (the key itself: tests/eval/test_seeds.py)."""

import pytest

from tools.seed_sweep import fresh_scratch, main


def test_scratch_is_kept_for_the_same_keys_its_models_alone_for_other_trial_inputs(tmp_path):
    out = tmp_path / "data" / "seed_sweep" / "seed_2"

    def made(models: str, outcomes: str) -> None:
        fresh_scratch(out, models, outcomes)
        for name in ("train", "sim_eval", "reports"):
            (out / name).mkdir(exist_ok=True)
            (out / name / "x").write_text(name)
        (out / "params.yaml").write_text("sim_eval: {}")

    made("m1", "k1")
    fresh_scratch(out, "m1", "k1")  # the same inputs: resume, everything kept
    assert all((out / n / "x").exists() for n in ("train", "sim_eval", "reports"))

    fresh_scratch(out, "m1", "k2")  # sim_eval's code or params changed, training's did not
    assert (out / "train" / "x").read_text() == "train"
    assert not any((out / n).exists() for n in ("sim_eval", "reports", "params.yaml"))
    assert (out / "inputs.sha256").read_text() == "k2"

    made("m1", "k2")
    fresh_scratch(out, "m2", "k2")  # training's data, code or params changed
    assert sorted(p.name for p in out.iterdir()) == ["inputs.sha256", "models.sha256"]
    assert (out / "models.sha256").read_text() == "m2"

    legacy = tmp_path / "data" / "seed_sweep" / "seed_3"  # made before stamps: not trusted
    (legacy / "train").mkdir(parents=True)
    (legacy / "inputs.sha256").write_text("k2")  # an outcomes stamp alone vouches for no model
    fresh_scratch(legacy, "m2", "k2")
    assert not (legacy / "train").exists()


def test_fewer_than_two_seeds_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--seeds", "1", "--params", str(tmp_path / "params.yaml")])
    assert "--seeds: at least 2" in capsys.readouterr().err


def test_extra_seeds_reach_table_i_through_sim_eval_on_the_tiny_dataset(tiny_evaluated, tmp_path):
    """The sweep trains and evaluates one extra seed; sim_eval rerun beside its file merges
    it: each seed's rates are those of its own evaluation, and a changed input un-merges it."""
    import json

    from stages import sim_eval

    params, data, _, _ = tiny_evaluated
    reports, scratch = tmp_path / "reports", tmp_path / "scratch"
    assert main(["--params", str(params), "--data-root", str(data), "--reports", str(reports),
                 "--seeds", "2", "--scratch", str(scratch)]) == 0
    runs = json.loads((reports / "seeds" / "seed_runs.json").read_text())
    assert set(runs["seeds"]) == {"8"}  # common.seed 7 + 1
    assert set(runs["seeds"]["8"]) == {"template_only", "sctdn", "vatmart", "vatmart@1",
                                       "skt_flow", "skt_flow@1"}

    def evaluate() -> dict:
        args = ["--params", str(params), "--data-root", str(data), "--data-dir",
                str(tmp_path / "eval"), "--reports-dir", str(reports / "sim_eval"),
                "--log-dir", str(tmp_path / "logs")]
        assert sim_eval.main(args) == 0
        return json.loads((reports / "sim_eval" / "metrics.json").read_text())

    m = evaluate()
    seeds = m["seeds"]
    assert seeds["status"] == "ok" and seeds["seeds"] == [7, 8]
    own = json.loads((scratch / "seed_8" / "reports" / "metrics.json").read_text())
    for method in ("template_only", "sctdn", "vatmart"):
        assert seeds[method]["success_per_seed"]["7"] == m[method]["success"]
        assert seeds[method]["success_per_seed"]["8"] == own[method]["success"]
    assert seeds["vatmart"]["success_single_per_seed"]["8"] == own["vatmart"]["success_single"]
    assert "oracle" not in seeds and "Table I over training seeds" in (
        reports / "sim_eval" / "report.md").read_text()

    original = params.read_text()
    try:  # the seeds were made under other params: not merged
        params.write_text(original + "\n# edited\n")
        assert evaluate()["seeds"]["status"] == "stale"
    finally:
        params.write_text(original)
