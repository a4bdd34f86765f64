"""Typed, validated parameters (``params.yaml``).

One pydantic model per params.yaml section. Unknown keys, missing keys, wrong types and
out-of-range values fail at load time with a :class:`~skt_lib.errors.ParamsError` whose
message names the offending key, e.g. ``mesh_gen.n_supports``.
All lengths are metres.
"""

from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from skt_lib.errors import ParamsError

LEVELS = ("easy", "normal", "hard", "very_hard")
OBJECT_CATEGORIES = ("mug", "cooking_utensil", "scissor", "tool", "other")

PositiveLength = Annotated[float, Field(gt=0.0, le=1.0)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


def _check_range(name: str, rng: tuple[float, float]) -> None:
    if rng[0] > rng[1]:
        raise ValueError(f"{name}: lower bound {rng[0]} is above upper bound {rng[1]}")


class CommonParams(_Section):
    seed: int = Field(ge=0, description="The one seed every generator is derived from.")


class ComputeParams(_Section):
    backend: Literal["local", "dask"] = Field(
        description="Per-item executor: local processes, or a Dask distributed cluster."
    )
    n_workers: int = Field(ge=1, le=256, description="Worker processes (local or LocalCluster).")
    scheduler_address: str | None = Field(
        default=None, description="Dask scheduler 'tcp://host:port'; null starts a LocalCluster."
    )


class MeshGenParams(_Section):
    n_supports: int = Field(ge=4, le=5000, description="Supporting items the train/val/test split is drawn from.")
    n_extra_train_supports: int = Field(
        default=0, ge=0, le=5000,
        description="Further supporting items, generated after the n_supports and all training: "
                    "more training data with the same validation and test supports.")
    n_val_per_level: int = Field(ge=0, description="Validation supports per difficulty level.")
    n_test_per_level: int = Field(ge=1, description="Test supports per difficulty level.")
    n_objects_per_category: int = Field(ge=2, le=100, description="Objects per category.")
    n_test_objects_per_category: int = Field(
        ge=1, le=99, description="Test objects per category (never used to make labels); the rest train."
    )
    support_radius_m: tuple[PositiveLength, PositiveLength] = Field(
        description="Range of the support tube's section half-width (round radius / square half-side)."
    )
    object_rod_radius_m: PositiveLength = Field(
        description="Every object's aperture admits a rod of at least this radius."
    )
    level_rise_m: tuple[PositiveLength, PositiveLength, PositiveLength] = Field(
        description="Blocking-height thresholds between easy|normal|hard|very_hard."
    )
    narrow_gap_m: PositiveLength = Field(
        description="Clearance above the hanging arm below which a support is one level harder."
    )
    curl_very_hard_deg: float = Field(
        gt=90.0, lt=360.0, description="Total tip turning above which a hook is very_hard."
    )
    density_kg_m3: float = Field(gt=10.0, lt=20000.0, description="Object material density.")

    @model_validator(mode="after")
    def _consistent(self) -> "MeshGenParams":
        _check_range("support_radius_m", self.support_radius_m)
        if not self.level_rise_m[0] < self.level_rise_m[1] < self.level_rise_m[2]:
            raise ValueError("level_rise_m: thresholds must increase strictly")
        if self.support_radius_m[1] >= self.object_rod_radius_m:
            raise ValueError(
                "support_radius_m: the thickest support must be thinner than object_rod_radius_m"
            )
        if self.n_test_objects_per_category >= self.n_objects_per_category:
            raise ValueError(
                f"n_test_objects_per_category: {self.n_test_objects_per_category} leaves no training "
                f"objects of {self.n_objects_per_category} per category"
            )
        n_fixed = 4 * (self.n_val_per_level + self.n_test_per_level)
        if n_fixed >= self.n_supports:
            raise ValueError(
                f"n_supports: {self.n_supports} leaves no training supports after "
                f"{n_fixed} val+test supports"
            )
        return self


class PerturbationParams(_Section):
    accel_m_s2: float = Field(ge=0.0, le=9.81, description="Sideways/outward gravity tilt (DESIGN §5).")
    steps_per_direction: int = Field(ge=1, le=100000, description="Steps per tilt direction.")
    settle_steps: int = Field(ge=1, le=100000, description="Steps under normal gravity after tilting.")
    rest_speed_m_s: float = Field(
        gt=0.0, le=0.5, description="At rest: the object's mean centre-of-mass speed over the final window must not exceed this, m/s.")
    rest_angular_speed_rad_s: float = Field(
        gt=0.0, le=5.0, description="At rest: the object's mean angular speed over the final window must not exceed this, rad/s.")
    rest_window_steps: int = Field(
        ge=1, le=10000, description="At rest: physics steps over which the object is observed after settling.")


class ContactSimParams(_Section):
    dt: float = Field(gt=0.0, le=0.01, description="Physics time step, s.")
    solver_iterations: int = Field(ge=1, le=1000, description="PyBullet solver iterations.")
    friction: float = Field(gt=0.0, le=2.0, description="Lateral friction of objects and supports.")
    linear_damping: float = Field(
        ge=0.0, le=5.0,
        description="Linear damping rate of free objects, 1/s (PyBullet multibody: force −k·m·v): air drag; damps long objects' pendulum swing.")
    angular_damping: float = Field(
        ge=0.0, le=20.0,
        description="Angular damping rate of free objects, 1/s (PyBullet multibody: torque −k·I·ω): air drag and contact losses, so a hung object stops swinging.")
    rod_radius_m: PositiveLength = Field(description="Radius of the horizontal test rod for objects.")
    n_drops: int = Field(ge=1, le=100, description="Release attempts per object / support.")
    drop_steps: int = Field(ge=1, le=100000, description="Steps under gravity after release.")
    perturb: PerturbationParams
    max_init_tries: int = Field(ge=1, le=1000, description="Draws for a collision-free release pose.")
    init_clearance_m: float = Field(gt=0.0, le=0.05, description="Min. distance at release.")
    pose_noise_deg: float = Field(ge=0.0, le=45.0, description="Random tilt of release poses.")
    roll_noise_deg: float = Field(ge=0.0, le=90.0, description="Random roll about the aperture axis.")
    slide_noise_m: float = Field(ge=0.0, le=0.05, description="Release offset along the arm.")
    release_gap_m: float = Field(
        gt=0.0, le=0.02,
        description="Gap between arm and aperture top at release; covers PyBullet's 1 mm hull margins.",
    )
    consistency_tol_m: float = Field(gt=0.0, le=0.05, description="Hangs agree if contacts are this close.")
    goal_clearance_m: float = Field(gt=0.0, le=0.01, description="Clearance of the stored hanging pose.")


class RotationExtractionParams(_Section):
    front_offset_m: float = Field(gt=0.0, le=0.5, description="How far P_front lies back along the approach.")


class RrtSktsParams(_Section):
    n_skts_per_support: int = Field(ge=1, le=500, description="Planned SKTs per support (paper: 50).")
    n_skts_per_test_support: int = Field(
        ge=1, le=500, description="Planned SKTs per test support: the oracles' stored choices in "
        "sim_eval (≥ n_skts_per_support; the first ones are the same).")
    planner: Literal["one_tree", "per_skt"] = Field(description="one_tree: every SKT of a support read out of one search grown from the hang, each to its own start (SKT 0 to the start region's centre); per_skt: today's reference, a fresh search per SKT, every SKT to the centre.")
    start_dx_m: tuple[float, float] = Field(description="Start keypoint offset range toward the robot.")
    start_dy_m: float = Field(ge=0.0, le=0.3, description="Start keypoint offset half-range along the wall.")
    start_dz_m: tuple[float, float] = Field(description="Start keypoint offset range upward.")
    step_m: float = Field(gt=0.001, le=0.05, description="Tree edge length of the threading planner.")
    max_turn_deg: float = Field(gt=0.0, le=90.0, description="Largest turn of the motion direction per edge.")
    lead_in_m: float = Field(gt=0.0, le=0.1, description="Straight final approach along the hanging keypoint's x.")
    max_release_offset_m: float = Field(ge=0.0, le=0.004, description="How far from the hang ξ_0 may be, lifted above it and/or moved back along the arrival (the object drops or slides in); ≤ 4 mm, so every SKT ends within 5 mm of the hang.")
    check_step_m: float = Field(gt=0.0, le=0.01, description="Largest probe-point motion between checked poses.")
    clearance_m: float = Field(ge=0.0, le=0.01, description="PyBullet distance the reference object keeps from support and wall.")
    probe_train_objects: bool = Field(description="Plan with the training objects beside the reference (docs/pipeline.md, rrt_skts).")
    penetration_tol_m: float = Field(ge=0.0, le=0.01, description="Deepest penetration allowed to a training object.")
    wall_train_objects: bool = Field(description="Keep every training object off the wall plane (its mesh's least x ≥ 0; exact and cheap, the wall is a plane) where the keypoint lies at least wall_from_m from the hang (docs/pipeline.md, rrt_skts).")
    wall_from_m: float = Field(ge=0.0, le=0.3, description="With wall_train_objects: the wall is checked for the training objects only this far from the hang and more (some cross it within millimetres of the reference's hang and settle off it).")
    train_objects_from_m: float = Field(ge=0.0, le=0.3, description="With probe_train_objects: the training objects in the probe are checked only where the keypoint lies at least this far from the hang (nearer, each object settles its own way and the reference alone decides).")
    goal_bias: float = Field(gt=0.0, lt=1.0, description="Share of tree samples drawn in the start region.")
    surface_bias: float = Field(ge=0.0, lt=1.0, description="Share of tree samples drawn near the support's surface.")
    route_bias: float = Field(ge=0.0, lt=1.0, description="Share of tree samples drawn near the hanging arm's threading route (from the mesh's skeleton: along the arm from the hang, over its tip and on past it).")
    route_spread_m: float = Field(gt=0.0, le=0.05, description="Spread (standard deviation per axis) of the samples about the threading route.")
    surface_offset_m: float = Field(gt=0.0, le=0.05, description="Largest offset of those samples from the surface, along its normal.")
    plane_bias: float = Field(ge=0.0, le=1.0, description="Share of tree samples (of every kind) moved onto the threading plane: the vertical plane through the hang that holds the hanging keypoint's x axis.")
    max_checks: int = Field(ge=100, le=10_000_000, description="Planning budget per SKT, in pose checks.")
    shortcut_steps: int = Field(ge=0, le=100000, description="Shortcut attempts on a found path.")
    dense_step_m: float = Field(gt=0.0, le=0.001, description="Spacing of stored keypoint positions (≤ 1 mm).")
    recheck_spacing_m: float = Field(gt=0.0, le=0.01, description="Surface sample spacing of the re-check.")
    recheck_step_m: float = Field(gt=0.0, le=0.002, description="Max object-point motion between re-checked poses.")

    @model_validator(mode="after")
    def _ranges(self) -> "RrtSktsParams":
        _check_range("start_dx_m", self.start_dx_m)
        _check_range("start_dz_m", self.start_dz_m)
        if self.start_dx_m[0] <= 0:
            raise ValueError("start_dx_m: starts must lie in front of the hang (> 0)")
        if self.goal_bias + self.surface_bias + self.route_bias >= 1.0:
            raise ValueError("route_bias: goal_bias + surface_bias + route_bias must be < 1")
        if self.dense_step_m > self.step_m:
            raise ValueError("dense_step_m: must not exceed step_m")
        if self.n_skts_per_test_support < self.n_skts_per_support:
            raise ValueError("n_skts_per_test_support: must be at least n_skts_per_support")
        return self


class RenderViewsParams(_Section):
    n_azimuth: int = Field(ge=1, le=64, description="Camera azimuths (n_azimuth × n_elevation views).")
    n_elevation: int = Field(ge=1, le=64, description="Camera elevations.")
    azimuth_deg: tuple[float, float] = Field(description="Azimuth span; 0 = in front (+x).")
    elevation_deg: tuple[float, float] = Field(description="Elevation span; positive = above.")
    distance_m: float = Field(gt=0.05, le=3.0, description="Camera distance from the support's centre.")
    fov_deg: float = Field(gt=5.0, lt=170.0, description="Vertical field of view.")
    width: int = Field(ge=16, le=4096, description="Image width, pixels.")
    height: int = Field(ge=16, le=4096, description="Image height, pixels.")
    n_points: int = Field(ge=16, le=100000, description="Points per view after farthest-point sampling.")
    noise_std_m: float = Field(ge=0.0, le=0.01, description="Depth noise along the ray; 0 = off.")
    sensor_severity: float = Field(0.0, ge=0.0, le=4.0, description="Depth-camera views (skt_lib/perception/camera_views.py): the wall in view, the sensor model of skt_lib/perception/sensor.py at this severity (1 = a structured-light / stereo camera's defaults), the support frame found from the wall as `skt predict --camera` finds it; 0 = a perfect ray cast of the support alone.")

    @model_validator(mode="after")
    def _ranges(self) -> "RenderViewsParams":
        _check_range("azimuth_deg", self.azimuth_deg)
        _check_range("elevation_deg", self.elevation_deg)
        if not -90 < self.elevation_deg[0] and self.elevation_deg[1] < 90:
            raise ValueError("elevation_deg: must lie strictly between -90 and 90")
        if not -90 <= self.azimuth_deg[0] and self.azimuth_deg[1] <= 90:
            raise ValueError("azimuth_deg: cameras must stay in front of the wall (|az| <= 90)")
        return self


class AffordanceMapsParams(_Section):
    sigma_m: float = Field(gt=0.0, le=0.05, description="Gaussian width of both maps (paper: 0.005).")
    alpha: float = Field(ge=0.0, le=1.0, description="Weight of the contact map.")
    beta: float = Field(ge=0.0, le=1.0, description="Weight of the segmentation map.")
    hanging_part_m: float = Field(gt=0.0, le=0.2, description="SKT arc length from ξ_0 that is the hanging part.")
    visible_tol_m: float = Field(gt=0.0, le=0.05, description="Contact visible if a cloud point is this close.")


class ClusteringParams(_Section):
    T: int = Field(ge=2, le=200, description="Waypoints per SKT (paper: 40; sweep 10/20/40).")
    k: int = Field(ge=1, le=50, description="Template families (paper: 5).")
    n_init: int = Field(ge=1, le=100, description="k-means++ restarts.")
    max_iter: int = Field(ge=1, le=10000, description="Lloyd iterations per restart.")


class TrainParams(_Section):
    epochs: int = Field(ge=1, le=10000, description="Training epochs.")
    views_per_epoch: int = Field(ge=1, le=1000, description="Random views per training support per epoch.")
    batch_size: int = Field(ge=1, le=1024, description="Clouds per step.")
    lr: float = Field(gt=0.0, le=1.0, description="Adam learning rate at the first epoch.")
    lr_final_ratio: float = Field(gt=0.0, le=1.0, description="Cosine decay: the last epoch's learning rate is lr × this.")
    weight_decay: float = Field(ge=0.0, le=1.0, description="Adam weight decay.")
    val_views: tuple[int, ...] = Field(min_length=1, description="Views of each val support evaluated.")
    centres: tuple[int, int, int] = Field(description="PointNet++ set-abstraction centres per level (paper: 512, 256, 64 and a fourth of 16).")
    nsample: int = Field(ge=1, le=128, description="Neighbours grouped per set-abstraction centre (paper: 32).")
    feat_dim: int = Field(ge=8, le=1024, description="Per-point feature width (affordance head and shape feature).")
    lstm_hidden: int = Field(ge=8, le=1024, description="Deformation LSTM hidden width (paper: 256).")
    contact_weight: float = Field(ge=0.0, le=100.0, description="Weight of the contact cross-entropy L_p (not in the paper; 0 switches it off).")
    hang_taper_waypoints: int = Field(ge=0, le=1000, description="Waypoints over which the deformation fades in from the hang: offset i is scaled by min(1, i / this), so ξ_0 stays where the template puts it, release_lift_m above the predicted contact (not in the paper; 0: deform every waypoint; must be < clustering.T).")
    check_families: int = Field(ge=0, le=100, description="SCTDN read-out (not in the paper): 0 returns the classifier's family, deformed; n ≥ 1 offers the deformed SKT and the aligned template of each of the n most probable families and returns the one whose reference ring cuts least into the input cloud (skt_lib.learning.cloud_check; must be ≤ clustering.k).")
    threads: int = Field(ge=1, le=256, description="Torch CPU threads while training (fixed, not the core count: float sums depend on it, so the same value gives the same weights on any machine).")


BASELINE_MODELS = ("sctdn_cp_feature", "vatmart", "vatmart_mod", "skt_flow")
METHODS = ("oracle", "oracle_floating", "template_only", "sctdn", "kpam", *BASELINE_MODELS,
           "omnihang")


class TrainBaselinesParams(_Section):
    models: tuple[Literal[BASELINE_MODELS], ...] = Field(
        description="Baselines trained with train's loop, data and budget: sctdn_cp_feature (Table II ablation: deformation conditioned on the contact-point feature), vatmart (CVAE on the contact-point feature), vatmart_mod (CVAE on the shape-conditioned feature), skt_flow (conditional flow matching over the SKT's control points, its samples ordered by the cloud check).")
    latent_dim: int = Field(ge=1, le=1024, description="VAT-Mart CVAE latent width (paper: 128).")
    hidden: int = Field(ge=8, le=4096, description="VAT-Mart CVAE encoder/decoder MLP width.")
    n_control_points: int = Field(ge=2, le=1000, description="VAT-Mart decoder: control points, linearly interpolated to the clustering.T waypoints (≤ T).")
    vatmart_kl_weight: float = Field(ge=0.0, le=10.0, description="KL weight of vatmart (paper: 0.1).")
    vatmart_mod_kl_weight: float = Field(ge=0.0, le=10.0, description="KL weight of vatmart_mod (paper: 0.01).")
    skt_flow_n_control: int = Field(ge=2, le=1000, description="skt_flow: control points it generates, linearly interpolated to the clustering.T waypoints (≤ T; 12 reproduce the validation SKTs to 0.65 mm mean, 8 to 1.0 mm).")
    skt_flow_steps: int = Field(ge=1, le=1000, description="skt_flow: Euler steps from noise to an SKT.")
    skt_flow_hidden: int = Field(ge=8, le=4096, description="skt_flow: width of its MLP (three hidden layers) that predicts the flow's end point.")
    skt_flow_draws: int = Field(ge=1, le=256, description="skt_flow: (noise, ground-truth SKT, time) draws per cloud per training step (the backbone runs once per cloud).")

    @model_validator(mode="after")
    def _unique(self) -> "TrainBaselinesParams":
        if len(set(self.models)) != len(self.models):
            raise ValueError(f"models: duplicate entries in {list(self.models)}")
        return self


class SimEvalParams(_Section):
    methods: tuple[Literal[METHODS], ...] = Field(
        min_length=1, description="Methods evaluated (Table I rows); oracle_floating: the oracle SKT carried by a floating hand (no arm); sctdn_cp_feature, vatmart, vatmart_mod, skt_flow need train_baselines to train them; omnihang plans with OMPL on the cloud, given the ground-truth hang.")
    n_proposals: int = Field(ge=1, le=100, description="Proposing methods (vatmart, vatmart_mod, skt_flow): proposals per support; a (support, object) trial succeeds if any proposal hangs (the paper's count); success_single counts the first proposal only (skt_flow's: the sample its cloud check ranks first).")
    omnihang_max_checks: int = Field(ge=100, le=10_000_000, description="omnihang: RRT-Connect budget per support, in collision checks (deterministic, unlike a time limit; a failed plan falls back to the straight approach).")
    robot_base_m: tuple[float, float, float] = Field(description="World position of the Panda base, m.")
    linear_damping: float = Field(ge=0.0, le=10.0, description="Object linear damping (1/s) while carried, released and perturbed; PyBullet's default 0.04, as the anchors' (DESIGN §5).")
    angular_damping: float = Field(ge=0.0, le=10.0, description="Object angular damping (1/s) while carried, released and perturbed; PyBullet's default 0.04.")
    settle_linear_damping: float = Field(ge=0.0, le=10.0, description="Object linear damping during the final settle only (an undamped hung object keeps swinging).")
    settle_angular_damping: float = Field(ge=0.0, le=10.0, description="Object angular damping during the final settle only.")
    grasp_pitch_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: approach axis pitched down from keypoint +x, degrees, tried in this order.")
    grasp_rolls_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: roll of the hand about its approach axis, degrees (inner loop of the order).")
    grasp_yaws_deg: tuple[float, ...] = Field(
        min_length=1, description="Grasp candidates: the approach turned about keypoint +z from keypoint +x, degrees (90: from the side; outer loop of the order).")
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
        return self


class Params(_Section):
    common: CommonParams
    compute: ComputeParams
    mesh_gen: MeshGenParams
    contact_sim: ContactSimParams
    rotation_extraction: RotationExtractionParams
    rrt_skts: RrtSktsParams
    render_views: RenderViewsParams
    affordance_maps: AffordanceMapsParams
    clustering: ClusteringParams
    train: TrainParams
    train_baselines: TrainBaselinesParams
    sim_eval: SimEvalParams

    @model_validator(mode="after")
    def _baselines_trained(self) -> "Params":
        untrained = [m for m in self.sim_eval.methods
                     if m in BASELINE_MODELS and m not in self.train_baselines.models]
        if untrained:
            raise ValueError(f"sim_eval.methods: {untrained} evaluated but not trained (add them "
                             "to train_baselines.models)")
        return self


def _format_error(source: str, err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"]) or "<root>"
        msg = e["msg"].removeprefix("Value error, ")
        got = f" (got {e['input']!r})" if e["type"] != "missing" and "input" in e else ""
        if e["type"] == "extra_forbidden":
            msg = "unknown key (misspelt?)"
            got = ""
        lines.append(f"{source}: {key}: {msg}{got}")
    return "\n".join(lines)


def parse_params(data: object, source: str = "params") -> Params:
    """Validate a params mapping; raise :class:`ParamsError` naming every bad key."""
    if not isinstance(data, dict):
        raise ParamsError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
    try:
        return Params.model_validate(data)
    except ValidationError as err:
        raise ParamsError(_format_error(source, err)) from None


def load_params(path: str | Path = "params.yaml") -> Params:
    """Read and validate ``params.yaml``."""
    path = Path(path)
    if not path.is_file():
        raise ParamsError(f"{path}: params file not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ParamsError(f"{path}: not valid YAML: {err}") from None
    return parse_params(data, str(path))
