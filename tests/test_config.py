from pathlib import Path

import pytest

from skt_lib.config.params_file import load_params, parse_params
from skt_lib.errors import ParamsError

ROOT = Path(__file__).resolve().parents[1]


def test_committed_params_load():
    p = load_params(ROOT / "params.yaml")
    assert p.mesh_gen.n_supports >= 100
    assert p.mesh_gen.n_test_per_level >= 5
    assert p.mesh_gen.n_val_per_level >= 10  # selection on >= 40 supports, not on noise


def test_negative_count_names_the_key(tiny_dict, write_params):
    tiny_dict["mesh_gen"]["n_supports"] = -3
    with pytest.raises(ParamsError) as err:
        load_params(write_params(tiny_dict))
    assert "mesh_gen.n_supports" in str(err.value)
    assert "-3" in str(err.value)


def test_misspelt_key_is_named(tiny_dict, write_params):
    tiny_dict["mesh_gen"]["n_suports"] = tiny_dict["mesh_gen"].pop("n_supports")
    with pytest.raises(ParamsError) as err:
        load_params(write_params(tiny_dict))
    msg = str(err.value)
    assert "mesh_gen.n_suports: unknown key" in msg
    assert "mesh_gen.n_supports" in msg  # and the real key is reported missing


def test_unknown_section_and_wrong_type(tiny_dict):
    tiny_dict["mesh_genn"] = {}
    tiny_dict["common"]["seed"] = "abc"
    with pytest.raises(ParamsError) as err:
        parse_params(tiny_dict)
    assert "mesh_genn" in str(err.value) and "common.seed" in str(err.value)


@pytest.mark.parametrize(
    "key,value,fragment",
    [
        ("support_radius_m", [0.006, 0.003], "lower bound"),
        ("level_rise_m", [0.02, 0.01, 0.04], "increase"),
        ("support_radius_m", [0.003, 0.02], "thinner than object_rod_radius_m"),
        ("n_test_per_level", 3, "leaves no training supports"),
        ("object_rod_radius_m", 5.0, "object_rod_radius_m"),
    ],
)
def test_out_of_range_values(tiny_dict, key, value, fragment):
    tiny_dict["mesh_gen"][key] = value
    with pytest.raises(ParamsError, match=fragment):
        parse_params(tiny_dict)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ParamsError, match="not found"):
        load_params(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("common: [unclosed")
    with pytest.raises(ParamsError, match="not valid YAML"):
        load_params(bad)


def test_an_evaluated_baseline_must_be_trained(tiny_dict):
    tiny_dict["sim_eval"]["methods"] = ["sctdn", "vatmart_mod"]
    tiny_dict["train_baselines"]["models"] = ["vatmart"]
    with pytest.raises(ParamsError, match=r"sim_eval.methods: \['vatmart_mod'\] evaluated but not "
                                          r"trained"):
        parse_params(tiny_dict)
    tiny_dict["train_baselines"]["models"] = ["vatmart", "vatmart"]
    with pytest.raises(ParamsError, match="train_baselines: models: duplicate"):
        parse_params(tiny_dict)
    tiny_dict["train_baselines"]["models"] = ["vatmart_mod"]
    tiny_dict["sim_eval"]["methods"] = ["sctdn", "vatmart_mod", "omnihang"]
    assert parse_params(tiny_dict).sim_eval.methods[-1] == "omnihang"
