"""tools/contact_label_spread.py: the contact label's spread over drop seeds."""

import json

import numpy as np
import pandas as pd
import pytest
import yaml

from tools.contact_label_spread import label_spread, main


def test_spread_is_the_largest_pairwise_distance():
    assert label_spread([[0, 0, 0]]) == 0.0
    assert label_spread([[0, 0, 0], [0.003, 0, 0], [0, 0.004, 0]]) == pytest.approx(0.005)


def test_the_stage_seed_reproduces_the_stored_label(tiny_dataset, tmp_path):
    params, data, _ = tiny_dataset
    seed = yaml.safe_load(params.read_text())["common"]["seed"]
    out = tmp_path / "spread.json"
    assert main(["--params", str(params), "--data-root", str(data), "--split", "all",
                 "--seeds", str(seed), str(seed + 1), "--out", str(out)]) == 0
    got = json.loads(out.read_text())
    contacts = pd.read_parquet(data / "contact_sim" / "contacts.parquet")
    stored = contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]].set_index("item_id")
    assert got["supports"] and set(got["supports"]) <= set(stored.index)
    for sid, row in got["supports"].items():
        assert len(row["labels"]) == 2
        # the stage's own seed gives the stage's label, bit for bit: the tool reruns the stage
        assert row["labels"][0] == list(stored.loc[sid, "contact_support"])
        assert row["spread_mm"] == pytest.approx(1000 * label_spread(row["labels"]))
        assert np.isfinite(row["spread_mm"])


def test_one_seed_is_refused(tiny_dataset, capsys):
    params, data, _ = tiny_dataset
    assert main(["--params", str(params), "--data-root", str(data), "--seeds", "1"]) == 2
    assert "at least two seeds" in capsys.readouterr().err
