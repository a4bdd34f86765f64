"""contact_sim and rotation_extraction on the tiny dataset."""

import json
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest

from skt_lib.config.params_file import load_params
from skt_lib.geometry.se3 import pose_matrix, skt_rotation
from skt_lib.io import read_table
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SUPPORTS
from skt_lib.sim.contact_sim import HangTask, arm_site, perturbation, release_pose
from skt_lib.sim import contact_sim as contact_sim_lib
from skt_lib.sim.hanging import Perturbation, check_hang, perturb, perturb_phases
from skt_lib.sim.keypoints import keypoint_from_hang, orthonormality_error
from skt_lib.sim.world import World
from stages import contact_sim
from tests.conftest import TINY

pytestmark = pytest.mark.slow


def _tables(data):
    return (read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id"),
            read_table(data / "mesh_gen" / "objects.parquet", OBJECTS),
            read_table(data / "contact_sim" / "contacts.parquet", CONTACTS))


def _hang_again(params_path, data, support_id, offset=(0.0, 0.0, 0.0)):
    """Place the reference at its stored hanging pose (+ offset), perturb, judge."""
    p = load_params(params_path).contact_sim
    supports, objects, contacts = _tables(data)
    row = contacts.set_index("item_id").loc[support_id]
    ref = objects[objects["is_reference"]].iloc[0]
    goal = pose_matrix(row["hang_position"], row["hang_quat"])
    goal[:3, 3] += offset
    with World(p.dt, p.solver_iterations) as world:
        world.add_wall()
        sup = world.load(str(data / "mesh_gen" / supports.loc[support_id, "urdf_path"]),
                         np.eye(4), fixed=True, friction=p.friction)
        obj = world.load(str(data / "mesh_gen" / ref["urdf_path"]), goal, fixed=False,
                         friction=p.friction, linear_damping=p.linear_damping,
                         angular_damping=p.angular_damping)
        start_clearance = world.min_distance(obj, sup)
        perturb(world, perturbation(p))
        return check_hang(world, obj, sup, perturbation(p)), world.pose_support(obj), goal, start_clearance


def test_contract_and_success(tiny_dataset):
    _, data, reports = tiny_dataset
    supports, objects, contacts = _tables(data)
    m = json.loads((reports / "contact_sim" / "metrics.json").read_text())
    assert m["n_supports"] == len(supports) == 12
    n_objects = 5 * TINY["mesh_gen"]["n_objects_per_category"]
    # a support fails only where no hang passes the evaluation's perturbation (one easy peg
    # of the tiny set: the ring slides off it under the undamped tilts)
    assert m["n_supports_ok"] + sum(m["n_supports_no_eval_stable_hang_by_level"].values()) \
        == m["n_supports"]
    assert m["support_success_rate"] >= 0.9 and m["n_objects_ok"] == m["n_objects"] == n_objects
    ok = contacts[contacts["ok"]]
    assert np.isfinite(np.stack(ok["hang_quat"])).all()
    assert (ok["goal_clearance_m"] >= 0.00025).all()  # stored goals are collision-free
    k = json.loads((reports / "rotation_extraction" / "metrics.json").read_text())
    assert k["n_keypoints"] == n_objects + 1 and k["max_orthonormality_error"] <= 1e-6
    kp = read_table(data / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    for r in kp.itertuples():
        rot = np.reshape(r.rotation, (3, 3))
        assert orthonormality_error(rot) <= 1e-9
        assert np.linalg.norm(r.position) < 0.06  # on the aperture, near the object origin


def test_stored_hanging_pose_is_stable_and_3cm_off_falls(tiny_dataset):
    params, data, _ = tiny_dataset
    _, _, contacts = _tables(data)
    for sid in contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]]["item_id"][:4]:
        check, pose, goal, clearance = _hang_again(params, data, sid)
        assert clearance > 0, sid  # collision-free goal
        assert check.ok, (sid, check.reason)
        # the ≈22° outward tilt may slide it along a straight arm, but not off it
        assert np.linalg.norm(pose[:3, 3] - goal[:3, 3]) < 0.03, sid
        off, _, _, _ = _hang_again(params, data, sid, offset=(0.0, 0.03, 0.0))
        assert not off.ok, sid
        assert off.reason in ("touches_floor", "no_contact")


def test_same_seed_same_table_on_one_or_two_workers(tiny_dataset, tmp_path):
    params, data, _ = tiny_dataset
    text = params.read_text().replace("n_workers: 1", "n_workers: 2")
    two = tmp_path / "two.yaml"
    two.write_text(text)
    out = tmp_path / "contact_sim"
    assert contact_sim.main(["--params", str(two), "--data-root", str(data), "--data-dir", str(out),
                             "--reports-dir", str(tmp_path / "rep"),
                             "--log-dir", str(tmp_path / "logs")]) == 0
    # no wall clock in the report: the same bytes on one or two workers
    assert (tmp_path / "rep" / "report.md").read_bytes() == \
        (data.parent / "reports" / "contact_sim" / "report.md").read_bytes()
    assert (out / "contacts.parquet").read_bytes() == \
        (data / "contact_sim" / "contacts.parquet").read_bytes()


def test_arm_site_walks_along_the_polyline():
    arm = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0, 0.1]], float)
    p, t = arm_site(arm, np.array([0.05, 0, 0.01]), 0.0)
    assert p == pytest.approx([0.05, 0, 0]) and t == pytest.approx([1, 0, 0])
    p, t = arm_site(arm, np.array([0.05, 0, 0]), 0.08)  # round the corner
    assert p == pytest.approx([0.1, 0, 0.03]) and t == pytest.approx([0, 0, 1])
    p, _ = arm_site(arm, np.array([0.05, 0, 0]), -1.0)  # clipped at the wall end
    assert p == pytest.approx([0, 0, 0])


def test_release_site_starts_at_the_hang_point_and_widens_only_when_redrawn():
    """A drop's first release is at the hang point (a random site made the contact label
    random along a straight peg); redraws move along the arm, at most slide_noise_m × the
    attempt's share of max_init_tries."""
    p = load_params(Path(__file__).resolve().parents[2] / "params.yaml").contact_sim  # the committed one
    task = HangTask("s", "reference_on_support", "o", "", 0.0, "s", "", ((0.0, 0.0, 0.0), (0.2, 0.0, 0.0)),
                    (0.1, 0.0, 0.0), 0.004, 0, p)
    rng = np.random.default_rng(0)
    for attempt in (0, 1, p.max_init_tries // 2, p.max_init_tries - 1):
        along = np.array([release_pose(rng, task, attempt)[0, 3] - 0.1 for _ in range(200)])
        reach = p.slide_noise_m * attempt / (p.max_init_tries - 1)
        assert np.abs(along).max() <= reach + 1e-12
        assert np.abs(along).max() >= 0.9 * reach  # and it does use the room it has
    assert np.abs(along).max() >= 0.9 * p.slide_noise_m


def test_keypoint_rule_on_known_poses():
    kp = keypoint_from_hang(np.eye(4), [0, 0, 0.02], 0.05)
    assert kp.rotation == pytest.approx(np.diag([-1.0, -1.0, 1.0]))  # x=-x, y=x×g, z=x×y
    assert kp.p_front - kp.p_hang == pytest.approx([0.05, 0, 0])
    tilt = pose_matrix([0.1, 0, -0.02], [0, 0, np.sin(0.2), np.cos(0.2)])
    kp = keypoint_from_hang(tilt, [0.0, 0.01, 0.02], 0.05)
    assert tilt[:3, :3] @ kp.rotation == pytest.approx(skt_rotation([-1, 0, 0]))
    with pytest.raises(ValueError, match="parallel to gravity"):
        skt_rotation([0, 0, -1])
    with pytest.raises(ValueError, match="contact_object"):
        keypoint_from_hang(np.eye(4), [np.nan, 0, 0], 0.05)


class _Recorder:
    """A stand-in world that records each phase: (gravity, steps, damping set before it)."""

    cid = 0

    def __init__(self):
        self.phases, self.damping, self._gravity = [], None, None

    def set_gravity_support(self, g):
        self._gravity = tuple(g)

    def step(self, n):
        self.phases.append((self._gravity, n, self.damping))


def test_goal_perturbation_is_the_evaluations_tilts_undamped_settle_damped(monkeypatch):
    world = _Recorder()
    monkeypatch.setattr(contact_sim_lib.pb, "changeDynamics",
                        lambda body, link, linearDamping, angularDamping, physicsClientId:
                        setattr(world, "damping", (linearDamping, angularDamping)))
    pert = Perturbation(4.0, 30, 50, 0.02, 0.15, 10)
    contact_sim_lib.perturb_as_evaluated(world, 7, pert, (0.04, 0.03, 1.0, 5.0))
    tilts, settle = world.phases[:-1], world.phases[-1]
    assert [(g, n) for g, n, _ in world.phases] == [(tuple(g), n) for g, n in perturb_phases(pert)]
    assert all(d == (0.04, 0.03) for _, _, d in tilts) and len(tilts) == 3
    assert settle[0] == (0.0, 0.0, -contact_sim_lib.G) and settle[2] == (1.0, 5.0)


def test_a_supports_goal_is_judged_by_the_evaluations_perturbation(tiny_dataset, monkeypatch):
    """simulate_hangs runs the goal check through perturb_as_evaluated with the task's
    (sim_eval's) damping, and every stored goal of the tiny run hangs again under it."""
    params_path, data, _ = tiny_dataset
    params = load_params(params_path)
    supports, objects, contacts = _tables(data)
    ref = objects[objects["is_reference"]].iloc[0]
    calls = []
    real = contact_sim_lib.perturb_as_evaluated
    monkeypatch.setattr(contact_sim_lib, "perturb_as_evaluated",
                        lambda w, o, p, d: (calls.append(d), real(w, o, p, d))[1])
    sid = supports.index[0]
    task = contact_sim_lib.reference_task(supports.loc[[sid]].reset_index().iloc[0], ref,
                                          data / "mesh_gen", 1, params.contact_sim,
                                          contact_sim_lib.eval_damping(params))
    row = contact_sim_lib.simulate_hangs(task)
    assert row["ok"] and calls and set(calls) == {contact_sim_lib.eval_damping(params)}
    assert contact_sim_lib.eval_damping(params)[:2] == (params.sim_eval.linear_damping,
                                                        params.sim_eval.angular_damping)
    # every stored goal, re-judged here at sim_eval's damping, hangs
    p, e = params.contact_sim, params.sim_eval
    for r in contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]].itertuples():
        with World(p.dt, p.solver_iterations) as world:
            world.add_wall()
            sup = world.load(str(data / "mesh_gen" / supports.loc[r.support_id, "urdf_path"]),
                             np.eye(4), fixed=True, friction=p.friction)
            obj = world.load(str(data / "mesh_gen" / ref["urdf_path"]),
                             pose_matrix(r.hang_position, r.hang_quat), fixed=False,
                             friction=p.friction, linear_damping=e.linear_damping,
                             angular_damping=e.angular_damping)
            phases = perturb_phases(perturbation(p))
            for i, (gravity, steps) in enumerate(phases):
                if i == len(phases) - 1:  # the settle damps, as the executor's
                    pb.changeDynamics(obj, -1, linearDamping=e.settle_linear_damping,
                                      angularDamping=e.settle_angular_damping,
                                      physicsClientId=world.cid)
                world.set_gravity_support(gravity)
                world.step(steps)
            assert check_hang(world, obj, sup, perturbation(p)).ok, r.support_id
