"""``sim_eval``: the methods, the Panda's set-up and execution, the trials."""

from typing import Literal

from pydantic import Field, model_validator

from skt_lib.config import Section
from skt_lib.config.physics import AngularDamping, LinearDamping, SettleAngularDamping, SettleLinearDamping
from skt_lib.config.proposals import Proposals
from skt_lib.config.train_baselines import BASELINE_MODELS

METHODS = ("oracle", "oracle_floating", "template_only", "sctdn", "kpam", *BASELINE_MODELS,
           "omnihang")


class SimEvalParams(Section):
    methods: tuple[Literal[METHODS], ...] = Field(
        min_length=1, description="Methods evaluated (Table I rows); oracle_floating: the oracle SKT carried by a floating hand (no arm); sctdn_cp_feature, vatmart, vatmart_mod, skt_flow need train_baselines to train them; omnihang plans with OMPL on the cloud, given the ground-truth hang.")
    n_proposals: Proposals
    flow_contacts: int = Field(
        ge=1, le=10, description="skt_flow: its samples start from this many contact hypotheses, the affordance's argmax and the next most afforded points 1 cm apart (skt_lib/eval/contact_hypotheses.py); 1: the argmax alone.")
    flow_samples: int = Field(
        ge=1, le=200, description="skt_flow: samples drawn per support, each moved clear of the cloud and ordered by the training objects carried along them (skt_lib/eval/probe_check.py); its n_proposals proposals are the first of them, its one SKT the very first; at least n_proposals.")
    omnihang_max_checks: int = Field(ge=100, le=10_000_000, description="omnihang: RRT-Connect budget per support, in collision checks (deterministic, unlike a time limit; a failed plan falls back to the straight approach).")
    robot_base_m: tuple[float, float, float] = Field(description="World position of the Panda base, m.")
    linear_damping: LinearDamping
    angular_damping: AngularDamping
    settle_linear_damping: SettleLinearDamping
    settle_angular_damping: SettleAngularDamping
    grasp_pitch_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: approach axis pitched down from keypoint +x, degrees, tried in this order.")
    grasp_rolls_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: roll of the hand about its approach axis, degrees (inner loop of the order).")
    grasp_yaws_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: the approach turned about keypoint +z from keypoint +x, degrees (90: from the side; outer loop of the order).")
    grasp_sphere_directions: int = Field(
        ge=0, le=200, description="Grasp candidates tried after the yaw/pitch/roll grid: approaches from this many directions spread over the whole sphere (from below and above too), each with every roll; 0: the grid only.")
    setup_clearance_m: float = Field(
        ge=0.0, le=0.02, description="Set-up: least robot–support, robot–wall and robot–object distance at the start pose, m.")
    setup_fallbacks: int = Field(
        ge=0, le=100, description="Set-up: how many of a checked learned method's other cloud-check candidates (sctdn, sctdn_cp_feature; clearest first) the Panda may run instead when no grasp follows its SKT; 0: the paper's protocol, a failed set-up ends the trial.")
    step_m: float = Field(gt=0.0, le=0.002, description="Max object-point motion per command (≤ 2 mm).")
    steps_per_command: int = Field(ge=1, le=100, description="Physics steps per joint command.")
    hold_steps: int = Field(ge=0, le=10000, description="Steps holding ξ_0 before the release.")
    track_tol_m: float = Field(gt=0.0, le=0.1, description="Keypoint tracking error that ends a trial.")
    ik_tol_m: float = Field(gt=0.0, le=0.02, description="Set-up IK: accepted position error.")
    ik_tol_rad: float = Field(gt=0.0, le=0.2, description="Set-up IK: accepted rotation error.")
    max_joint_step_rad: float = Field(gt=0.0, le=1.0, description="Set-up IK: max joint change per command.")
    ik_restarts: int = Field(ge=1, le=100, description="Set-up IK: start configurations tried per grasp candidate.")
    grasp_force_n: float = Field(gt=0.0, le=1000.0, description="Force limit of the rigid hold.")
    retreat_m: float = Field(ge=0.0, le=0.3, description="Retreat of the open hand toward the robot.")
    retreat_steps: int = Field(ge=1, le=10000, description="Steps of the retreat.")
    kpam_pre_hang_m: tuple[float, float, float] = Field(
        description="kPAM baseline: pre-hang keypoint offset from the hang (support frame).")
    kpam_lift_m: float = Field(ge=0.0, le=0.05, description="kPAM baseline: release this high above the hang.")
    n_record: int = Field(ge=0, le=100, description="Rollouts per method recorded to Rerun.")
    record_every: int = Field(ge=1, le=1000, description="Physics steps between recorded frames.")
    extra_supports: tuple[str, ...] = Field(
        default=(), description="Imported supports (skt import-support names) evaluated as extra rows, never in Table I.")
    extra_objects: tuple[str, ...] = Field(
        default=(), description="Imported objects (skt import-object names) evaluated as extra rows, never in Table I.")

    @model_validator(mode="after")
    def _grasps(self) -> "SimEvalParams":
        if any(not 0.0 <= a < 90.0 for a in self.grasp_pitch_deg):
            raise ValueError(f"grasp_pitch_deg: each pitch must lie in [0, 90) degrees, got {list(self.grasp_pitch_deg)}")
        for key in ("grasp_rolls_deg", "grasp_yaws_deg"):
            if any(not -180.0 <= a <= 180.0 for a in getattr(self, key)):
                raise ValueError(f"{key}: each angle must lie in [-180, 180] degrees, got {list(getattr(self, key))}")
        for key in ("grasp_pitch_deg", "grasp_rolls_deg", "grasp_yaws_deg", "methods"):
            values = getattr(self, key)
            if len(set(values)) != len(values):
                raise ValueError(f"{key}: duplicate entries in {list(values)}")
        if self.flow_samples < self.n_proposals:
            raise ValueError(f"flow_samples: skt_flow's {self.n_proposals} proposals (n_proposals) "
                             f"are the first of its samples; need at least as many, got "
                             f"{self.flow_samples}")
        return self
