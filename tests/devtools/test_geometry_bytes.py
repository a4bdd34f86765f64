"""tools.geometry_bytes builds exactly the files mesh_gen writes, and names what differs."""

import json

from stages import mesh_gen
from tools import geometry_bytes


def test_builds_the_stage_files_and_names_differences(tmp_path, write_params, tiny_dict):
    params = write_params(tiny_dict)
    data = tmp_path / "data"
    assert mesh_gen.main(["--params", str(params), "--data-dir", str(data),
                          "--reports-dir", str(tmp_path / "rep"), "--log-dir",
                          str(tmp_path / "logs")]) == 0
    built = geometry_bytes.build_all(params, tmp_path / "built", workers=2)
    stage = geometry_bytes.file_md5s(data)
    # every OBJ and URDF of every item, byte for byte what the stage wrote
    assert len(built) == 3 * (12 + 11) and built == stage
    assert geometry_bytes.compare(built, stage) == []

    theirs = dict(stage)
    some = sorted(theirs)[5]
    theirs[some] = "0" * 32
    del theirs[sorted(theirs)[0]]
    assert geometry_bytes.compare(built, theirs) == sorted([some, sorted(stage)[0]])

    # the command line: exit 1 and the path of a differing file against another environment
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"md5": theirs}))
    assert geometry_bytes.main(["--params", str(params), "--against", str(other),
                                "--workers", "1", "--json", str(tmp_path / "ours.json")]) == 1
    assert json.loads((tmp_path / "ours.json").read_text())["md5"] == stage
    other.write_text(json.dumps({"md5": stage}))
    assert geometry_bytes.main(["--params", str(params), "--against", str(other),
                                "--workers", "1"]) == 0
