"""tools/seed_sweep.py: a seed's scratch outputs are reused only for the data they were made from."""

from tools.seed_sweep import fresh_scratch, inputs_key


def test_scratch_is_kept_for_the_same_inputs_and_wiped_for_others(tmp_path):
    repo = tmp_path / "repo"
    (repo / "data").mkdir(parents=True)
    params, lock = repo / "params.yaml", repo / "dvc.lock"
    params.write_text("common: {seed: 1}\n")
    lock.write_text("stages: {train: {outs: [md5: a]}}\n")
    out = repo / "data" / "seed_sweep" / "seed_2"
    key = inputs_key(params, repo / "data")
    fresh_scratch(out, key)
    (out / "model.pt").write_text("trained")
    fresh_scratch(out, inputs_key(params, repo / "data"))  # same data: resume
    assert (out / "model.pt").read_text() == "trained"

    lock.write_text("stages: {train: {outs: [md5: b]}}\n")  # the data changed
    fresh_scratch(out, inputs_key(params, repo / "data"))
    assert not (out / "model.pt").exists() and (out / "inputs.sha256").is_file()

    (out / "model.pt").write_text("trained")
    params.write_text("common: {seed: 2}\n")  # the params changed
    fresh_scratch(out, inputs_key(params, repo / "data"))
    assert not (out / "model.pt").exists()

    legacy = repo / "data" / "seed_sweep" / "seed_3"  # made before stamps: not trusted
    legacy.mkdir()
    (legacy / "model.pt").write_text("old")
    fresh_scratch(legacy, inputs_key(params, repo / "data"))
    assert not (legacy / "model.pt").exists()
