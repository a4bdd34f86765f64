"""Shared fixtures, built in code: no network, no files outside tmp_path."""

import pytest
import yaml

from skt_lib.config.params_file import parse_params

TINY = {
    "common": {"seed": 7},
    "compute": {"backend": "local", "n_workers": 1, "scheduler_address": None},
    "mesh_gen": {
        "n_supports": 12,
        "n_val_per_level": 1,  # train selects on val: no split, no model (stages/train.py)
        "n_test_per_level": 1,
        "n_objects_per_category": 2,
        "n_test_objects_per_category": 1,
        "support_radius_m": [0.003, 0.006],
        "object_rod_radius_m": 0.01,
        "level_rise_m": [0.006, 0.02, 0.04],
        "narrow_gap_m": 0.04,
        "curl_very_hard_deg": 200.0,
        "density_kg_m3": 700.0,
    },
    "contact_sim": {'dt': 0.004166666666666667, 'solver_iterations': 50, 'friction': 0.6, 'linear_damping': 1.0, 'angular_damping': 5.0, 'rod_radius_m': 0.005, 'n_drops': 3, 'drop_steps': 480, 'perturb': {'accel_m_s2': 4.0, 'steps_per_direction': 240, 'settle_steps': 960, 'rest_speed_m_s': 0.02, 'rest_angular_speed_rad_s': 0.15, 'rest_window_steps': 120}, 'max_init_tries': 40, 'init_clearance_m': 0.001, 'pose_noise_deg': 6.0, 'roll_noise_deg': 15.0, 'slide_noise_m': 0.03, 'release_gap_m': 0.004, 'consistency_tol_m': 0.01, 'goal_clearance_m': 0.0005},
    "rotation_extraction": {'front_offset_m': 0.05},
    "render_views": {'n_azimuth': 7, 'n_elevation': 6, 'azimuth_deg': [-60.0, 60.0], 'elevation_deg': [-20.0, 55.0], 'distance_m': 0.35, 'fov_deg': 40.0, 'width': 320, 'height': 240, 'n_points': 1000, 'noise_std_m': 0.0},
    "affordance_maps": {'sigma_m': 0.005, 'alpha': 0.5, 'beta': 0.5, 'hanging_part_m': 0.03, 'visible_tol_m': 0.005},
    "clustering": {'T': 10, 'k': 2, 'n_init': 10, 'max_iter': 300},
    "train": {'epochs': 1, 'views_per_epoch': 1, 'batch_size': 16, 'lr': 0.001, 'lr_final_ratio': 0.05, 'weight_decay': 0.0001, 'val_views': [0], 'centres': [128, 32, 8], 'nsample': 16, 'feat_dim': 64, 'lstm_hidden': 64, 'contact_weight': 0.1, 'hang_taper_waypoints': 0, 'check_families': 0, 'threads': 1},
    "train_baselines": {"models": ["sctdn_cp_feature", "vatmart", "vatmart_mod", "skt_flow"], "latent_dim": 16,
                        "hidden": 64, "n_control_points": 4, "vatmart_kl_weight": 0.1, "vatmart_mod_kl_weight": 0.01,
                        "skt_flow_n_control": 4, "skt_flow_steps": 4, "skt_flow_hidden": 32, "skt_flow_draws": 2},
    "sim_eval": {"methods": ["oracle", "oracle_floating", "template_only", "sctdn", "kpam",
                             "vatmart", "skt_flow", "omnihang"],
                 "n_proposals": 3, "flow_contacts": 2, "flow_samples": 5,
                 "omnihang_max_checks": 20000,
                 "robot_base_m": [0.15, 0.0, 0.3], "linear_damping": 0.04, "angular_damping": 0.04,
                 "settle_linear_damping": 1.0, "settle_angular_damping": 5.0, "grasp_pitch_deg": [45.0, 30.0, 60.0],
                 "grasp_rolls_deg": [0.0, 180.0], "grasp_yaws_deg": [0.0], "grasp_sphere_directions": 4, "setup_clearance_m": 0.002, "setup_fallbacks": 3, "step_m": 0.002, "steps_per_command": 2, "hold_steps": 60,
                 "track_tol_m": 0.02, "ik_tol_m": 0.002, "ik_tol_rad": 0.02, "max_joint_step_rad": 0.2,
                 "ik_restarts": 4, "grasp_force_n": 60.0, "retreat_m": 0.08, "retreat_steps": 60,
                 "kpam_pre_hang_m": [0.1, 0.0, 0.0], "kpam_lift_m": 0.01,
                 "n_record": 1, "record_every": 16},
    "rrt_skts": {'n_skts_per_support': 1, 'n_skts_per_test_support': 1, 'planner': 'one_tree', 'start_dx_m': [0.08, 0.16], 'start_dy_m': 0.05, 'start_dz_m': [0.0, 0.1], 'step_m': 0.01, 'max_turn_deg': 35.0, 'lead_in_m': 0.01, 'max_release_offset_m': 0.004, 'check_step_m': 0.0025, 'clearance_m': 0.0005, 'probe_train_objects': False, 'penetration_tol_m': 0.005, 'wall_train_objects': True, 'wall_from_m': 0.01, 'train_objects_from_m': 0.03, 'goal_bias': 0.2, 'surface_bias': 0.2, 'surface_offset_m': 0.015, 'route_bias': 0.2, 'route_spread_m': 0.003, 'plane_bias': 0.6, 'max_checks': 15000, 'shortcut_steps': 10, 'dense_step_m': 0.001, 'recheck_spacing_m': 0.002, 'recheck_step_m': 0.001},
}


@pytest.fixture
def tiny_dict():
    import copy

    return copy.deepcopy(TINY)


@pytest.fixture
def tiny_params(tiny_dict):
    return parse_params(tiny_dict)


@pytest.fixture
def write_params(tmp_path):
    def _write(data, name="params.yaml"):
        path = tmp_path / name
        path.write_text(yaml.safe_dump(data))
        return path

    return _write


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """mesh_gen → … → train_baselines, run once on TINY params.

    Returns (params path, data root, reports root)."""
    from stages import (
        affordance_maps, clustering, contact_sim, mesh_gen, render_views, rotation_extraction,
        rrt_skts, train, train_baselines,
    )

    root = tmp_path_factory.mktemp("tiny")
    params = root / "params.yaml"
    params.write_text(yaml.safe_dump(TINY))
    data, reports = root / "data", root / "reports"
    for stage in (mesh_gen, contact_sim, rotation_extraction, rrt_skts, render_views,
                  affordance_maps, clustering, train, train_baselines):
        name = stage.__name__.rsplit(".", 1)[-1]
        assert stage.main(["--params", str(params), "--data-root", str(data),
                           "--data-dir", str(data / name), "--reports-dir", str(reports / name),
                           "--log-dir", str(root / "logs")]) == 0
    # wall-clock figures go to the run log, never into a report
    assert {p.stem for p in (root / "logs").glob("*.json")} >= {"contact_sim", "render_views"}
    return params, data, reports


@pytest.fixture(scope="session")
def tiny_evaluated(tiny_dataset, tmp_path_factory):
    """sim_eval on the tiny dataset, run once: (params, data root, sim_eval data, reports)."""
    from stages import sim_eval

    params, data, _ = tiny_dataset
    root = tmp_path_factory.mktemp("sim_eval")
    out, rep = root / "data" / "sim_eval", root / "reports"
    assert sim_eval.main(["--params", str(params), "--data-root", str(data), "--data-dir", str(out),
                          "--reports-dir", str(rep), "--log-dir", str(root / "logs")]) == 0
    return params, data, out, rep


def assert_same_tree(a, b) -> None:
    """Same relative file paths under ``a`` and ``b``, same bytes in each (names them all)."""
    from pathlib import Path

    def tree(root):
        return {p.relative_to(root).as_posix() for p in Path(root).rglob("*") if p.is_file()}

    fa, fb = tree(a), tree(b)
    assert fa == fb, f"{a} vs {b}: only in first {sorted(fa - fb)}, only in second {sorted(fb - fa)}"
    differ = [f for f in sorted(fa) if (Path(a) / f).read_bytes() != (Path(b) / f).read_bytes()]
    assert not differ, f"{a} vs {b}: {len(differ)} of {len(fa)} files differ: {differ}"
