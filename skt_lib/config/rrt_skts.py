"""``rrt_skts``: the threading planner and the re-check."""

from typing import Literal

from pydantic import Field, model_validator

from skt_lib.config import Section, check_range


class RrtSktsParams(Section):
    n_skts_per_support: int = Field(ge=1, le=500, description="Planned SKTs per support (paper: 50).")
    n_skts_per_test_support: int = Field(
        ge=1, le=500, description="Planned SKTs per test support: the oracles' stored choices in "
        "sim_eval (≥ n_skts_per_support; with probe_train_objects false the first ones are the ones any split gets).")
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
    probe_train_objects: bool | Literal["test"] = Field(description="Plan with the training objects beside the reference (docs/pipeline.md, rrt_skts): true on every support; \"test\" on test supports only, the first n_skts_per_support SKTs, the reference's others kept behind them.")
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
        check_range("start_dx_m", self.start_dx_m)
        check_range("start_dz_m", self.start_dz_m)
        if self.start_dx_m[0] <= 0:
            raise ValueError("start_dx_m: starts must lie in front of the hang (> 0)")
        if self.goal_bias + self.surface_bias + self.route_bias >= 1.0:
            raise ValueError("route_bias: goal_bias + surface_bias + route_bias must be < 1")
        if self.dense_step_m > self.step_m:
            raise ValueError("dense_step_m: must not exceed step_m")
        if self.n_skts_per_test_support < self.n_skts_per_support:
            raise ValueError("n_skts_per_test_support: must be at least n_skts_per_support")
        return self
