"""The user-item store (:mod:`skt_lib.items`): an import record that is not what
``skt import-*`` writes is one error naming the record and key, before any mesh is read."""

import json

import pytest

from skt_lib.config.params_file import parse_params
from skt_lib.errors import DataError, InputError
from skt_lib.eval.user_items import load_user_items
from skt_lib.items import OBJECT_RECORD, SUPPORT_RECORD, find_object, find_support, user_dir


def _record(root, kind, name, data) -> str:
    d = user_dir(root, kind, name)
    d.mkdir(parents=True)
    path = d / (SUPPORT_RECORD if kind == "support" else OBJECT_RECORD)
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.parametrize("keypoint", [None, "eye", [1.0] * 15, [[1.0] * 4] * 3,
                                      [float("nan")] + [0.0] * 15])
def test_an_object_record_without_a_4x4_keypoint(tmp_path, tiny_params, keypoint):
    path = _record(tmp_path, "object", "mug", {} if keypoint is None else {"keypoint": keypoint})
    with pytest.raises(DataError, match=f"{path}: 'keypoint' is not a finite 4×4 matrix"):
        find_object("mug", tmp_path, tiny_params)


@pytest.mark.parametrize("skts", [[[[0.0, 0.0, 0.0]]], [[[0.0, 0.0]] * 5], [["a", "b", "c"]],
                                  "oops", [[[0.0, 0.0, float("inf")]] * 4]])
def test_a_support_record_with_malformed_skts(tmp_path, tiny_params, skts):
    path = _record(tmp_path, "support", "hook", {"skts": skts})
    with pytest.raises(DataError, match=f"{path}: 'skts' is not a list of"):
        find_support("hook", tmp_path, tiny_params)


def test_a_record_that_is_not_a_json_object(tmp_path, tiny_params):
    path = _record(tmp_path, "object", "mug", [1, 2, 3])
    with pytest.raises(DataError, match=f"{path}: not an import record"):
        find_object("mug", tmp_path, tiny_params)


def test_a_support_without_skts_is_refused_where_the_ground_truth_is_needed(tmp_path,
                                                                             tiny_params):
    path = _record(tmp_path, "support", "hook", {"difficulty": "easy"})
    with pytest.raises(InputError, match=f"hook: has no ground-truth SKT in {path} \\(no "
                                         "'skts'\\); the oracle needs it$"):
        find_support("hook", tmp_path, tiny_params, gt_for="the oracle needs it")


def test_sim_eval_refuses_an_extra_support_without_skts_for_privileged_methods(
        tmp_path, tiny_dict):
    _record(tmp_path, "support", "hook", {"difficulty": "easy"})
    tiny_dict["sim_eval"]["extra_supports"] = ["hook"]
    params = parse_params(tiny_dict)
    with pytest.raises(InputError, match=r"hook: has no ground-truth SKT in .*; sim_eval.methods "
                                         r"\['oracle', 'oracle_floating', 'kpam', 'omnihang'\] "
                                         "need one"):
        load_user_items(tmp_path, params)
