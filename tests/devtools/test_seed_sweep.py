"""tools/seed_sweep.py: a seed's scratch outputs are reused only for the inputs they were made
from (the key itself: tests/eval/test_seeds.py)."""

import pytest

from tools.seed_sweep import fresh_scratch, main


def test_scratch_is_kept_for_the_same_key_and_wiped_for_another(tmp_path):
    out = tmp_path / "data" / "seed_sweep" / "seed_2"
    fresh_scratch(out, "k1")
    (out / "model.pt").write_text("trained")
    fresh_scratch(out, "k1")  # the same inputs: resume
    assert (out / "model.pt").read_text() == "trained"

    fresh_scratch(out, "k2")  # the data, code or params changed
    assert not (out / "model.pt").exists() and (out / "inputs.sha256").read_text() == "k2"

    legacy = tmp_path / "data" / "seed_sweep" / "seed_3"  # made before stamps: not trusted
    legacy.mkdir()
    (legacy / "model.pt").write_text("old")
    fresh_scratch(legacy, "k2")
    assert not (legacy / "model.pt").exists()


def test_fewer_than_two_seeds_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--seeds", "1", "--params", str(tmp_path / "params.yaml")])
    assert "--seeds: at least 2" in capsys.readouterr().err
