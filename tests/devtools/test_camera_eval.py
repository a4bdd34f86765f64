"""tools/camera_eval.py: every learned row on depth-camera views, judged against its own clean
success on the same views; the default predictor's extra seeds only when current."""

import json
import shutil

import numpy as np
import pytest

from skt_lib.eval.seeds import models_key
from tools.camera_eval import DEFAULT_METHOD, main


@pytest.fixture(scope="module")
def camera_run(tiny_dataset, tmp_path_factory):
    params, data, _ = tiny_dataset
    root = tmp_path_factory.mktemp("camera")
    (root / "params.yaml").write_text(params.read_text())
    view = root / "data"  # the tiny data, plus make seeds' scratch of two extra seeds
    view.mkdir()
    for entry in data.iterdir():
        (view / entry.name).symlink_to(entry)
    for seed, stamp in ((8, models_key(root)), (9, "stale")):
        d = view / "seed_sweep" / f"seed_{seed}" / "train_baselines" / DEFAULT_METHOD
        shutil.copytree(data / "train_baselines" / DEFAULT_METHOD, d)
        (d.parents[1] / "models.sha256").write_text(stamp)
    rep = root / "reports"
    code = main(["--params", str(root / "params.yaml"), "--data-root", str(view),
                 "--reports-dir", str(rep), "--views", "1", "--severities", "0", "1",
                 "--hang-severities", "0", "1", "--methods", "sctdn", DEFAULT_METHOD])
    assert code == 0
    return (json.loads((rep / "metrics.json").read_text()),
            json.loads((rep / "outcomes.json").read_text()), rep)


def test_every_row_runs_on_the_same_views_and_current_seeds_only(camera_run):
    m, outcomes, rep = camera_run
    one = f"{DEFAULT_METHOD}@1"
    # seed 9's stamp is not today's; an extra seed runs the one-SKT row only
    assert set(outcomes) == {"sctdn", one, DEFAULT_METHOD, f"{one} seed 8"}
    for label in outcomes:
        keys = {"0/true", "0/up", "1/true", "1/up"}
        if label in (one, DEFAULT_METHOD):  # the default predictor's model: every mode
            keys |= {"0/assumed", "1/assumed", "1/level"}
        assert set(outcomes[label]) == keys, label
        views = {k: set(v) for k, v in outcomes[label].items()}
        assert all(v == views["0/true"] for v in views.values()), label
    for key, flags in outcomes[one].items():  # the best of N never loses a view the first hung
        assert all(outcomes[DEFAULT_METHOD][key][v] for v, ok in flags.items() if ok)
    # the same model again (a seed copy), the same latents and views: the same verdicts
    assert outcomes[f"{one} seed 8"] == {k: v for k, v in outcomes[one].items()
                                         if k in outcomes[f"{one} seed 8"]}
    assert (rep / "report.md").read_text().count(f"`{one}`") >= 2
    assert (rep / "frame_errors.png").stat().st_size > 0


def test_rates_and_kept_ratios_come_from_the_outcomes(camera_run):
    m, outcomes, _ = camera_run
    for label, k in m["kept"].items():
        rate = {key: np.mean(list(v.values())) for key, v in outcomes[label].items()}
        assert m["hang"][label]["1/up"]["success"] == pytest.approx(rate["1/up"])
        assert k["clean"] == pytest.approx(rate["0/true"])
        if rate["0/true"] > 0:
            assert k["all"] == pytest.approx(rate["1/up"] / rate["0/true"])
        assert k["paired"]["difference"] == pytest.approx(rate["1/up"] - rate["0/true"])
    s = m["seeds"][f"{DEFAULT_METHOD}@1"]
    assert s["rows"] == [f"{DEFAULT_METHOD}@1", f"{DEFAULT_METHOD}@1 seed 8"]
    assert s["mean"]["0/true"]["all"] == pytest.approx(m["kept"][f"{DEFAULT_METHOD}@1"]["clean"])


def test_the_clean_reference_must_be_hung(capsys):
    with pytest.raises(SystemExit):
        main(["--hang-severities", "1"])
    assert "must include 0" in capsys.readouterr().err


def test_each_mode_feeds_the_models_what_skt_predict_would(tiny_dataset):
    from skt_lib.cli.predict import predict_camera, predict_cloud
    from skt_lib.config.params_file import load_params
    from skt_lib.geometry.export import read_obj
    from skt_lib.geometry.se3 import transform_points
    from skt_lib.learning.predictor import SktPredictor
    from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
    from skt_lib.perception.views import support_cameras
    from skt_lib.perception.wall_frame import WallSettings
    from tools.camera_eval import _ready_modes

    params_path, data, _ = tiny_dataset
    p = load_params(params_path).render_views
    import pandas as pd

    mesh_path = pd.read_parquet(data / "mesh_gen" / "supports.parquet")["mesh_path"].iloc[0]
    (mesh,) = read_obj(data / "mesh_gen" / mesh_path)
    cam = camera_view(CameraScene(mesh), support_cameras(mesh, p)[3].pose(),
                      Intrinsics(p.width, p.height, p.fov_deg), SensorModel().at(1.0),
                      np.random.default_rng(0))
    predictor = SktPredictor.load(data / "train")
    got = _ready_modes(predictor.cfg, cam, ["true", "assumed", "up"], "view")
    up = cam.pose[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    want = predict_camera(predictor, cam.points, up, name="view")
    assert np.array_equal(got["ready"]["up"][0], want.points)
    assert np.array_equal(got["ready"]["up"][1], want.camera_to_support)
    for mode, frame in (("true", cam.pose), ("assumed", cam.assumed)):
        moved = transform_points(frame, cam.points)
        want = predict_cloud(predictor, moved[moved[:, 0] > WallSettings.off_wall_m])
        assert np.array_equal(got["ready"][mode][0], want.points), mode
        assert np.array_equal(got["ready"][mode][1], frame), mode
    assert not np.allclose(cam.assumed, cam.pose)  # severity 1: the assumed pose is off


def test_rows_and_kept_ratios_on_known_verdicts():
    import pandas as pd

    from tools.camera_eval import row_tables
    from tools.camera_report import _kept, _over_seeds

    def rows(label, method, first, anyone):  # 4 views: 2 easy, 2 hard; clean and 1/up
        out = []
        for key, f, a in (("0/true", first[:4], anyone[:4]), ("1/up", first[4:], anyone[4:])):
            sev, mode = key.split("/")
            for i in range(4):
                out.append({"label": label, "method": method, "support_id": f"s{i // 2}",
                            "difficulty": "easy" if i < 2 else "hard", "object_id": "o",
                            "view": i, "severity": float(sev), "mode": mode,
                            "success": f[i], "success_any": a[i], "failure_reason": ""})
        return out

    t = pd.DataFrame(rows("skt_flow", "skt_flow", [1, 1, 1, 0, 1, 0, 1, 0],
                          [1, 1, 1, 1, 1, 1, 1, 1])
                     + rows("skt_flow seed 5", "skt_flow", [1, 0, 1, 0, 1, 0, 0, 0],
                            [1, 1, 1, 1, 1, 1, 1, 1])
                     + rows("sctdn", "sctdn", [1, 1, 0, 0, 1, 0, 0, 0], [0] * 8))
    t[["success", "success_any"]] = t[["success", "success_any"]].astype(bool)
    got = row_tables(t)
    assert set(got) == {"skt_flow@1", "skt_flow", "skt_flow@1 seed 5", "sctdn"}
    assert got["skt_flow"]["success"].all()  # best of N: any proposal
    assert got["sctdn"]["success"].sum() == 3  # not a proposer: its own verdicts
    k = _kept(got["skt_flow@1"], np.random.default_rng(0))
    assert k["clean"] == 0.75 and k["camera"] == 0.5 and k["all"] == pytest.approx(0.5 / 0.75)
    assert k["by_level"] == {"easy": 0.5, "hard": 1.0} and k["worst_level_name"] == "easy"
    assert not k["meets"] and k["paired"]["difference"] == -0.25
    s = _over_seeds(got)["skt_flow@1"]  # clean 0.75 and 0.5, camera 0.5 and 0.25
    assert s["mean"]["0/true"]["all"] == 0.625 and s["kept"]["all"] == pytest.approx(0.6)
    assert s["range"]["1/up"]["all"] == [0.25, 0.5]
