"""``contact_sim``: objects hung on the rod and the reference on every support."""

from pydantic import Field

from skt_lib.config import PositiveLength, Section


class PerturbationParams(Section):
    accel_m_s2: float = Field(ge=0.0, le=9.81, description="Sideways/outward gravity tilt (docs/design.md §5).")
    steps_per_direction: int = Field(ge=1, le=100000, description="Steps per tilt direction.")
    settle_steps: int = Field(ge=1, le=100000, description="Steps under normal gravity after tilting.")
    rest_speed_m_s: float = Field(
        gt=0.0, le=0.5, description="At rest: the object's mean centre-of-mass speed over the final window must not exceed this, m/s.")
    rest_angular_speed_rad_s: float = Field(
        gt=0.0, le=5.0, description="At rest: the object's mean angular speed over the final window must not exceed this, rad/s.")
    rest_window_steps: int = Field(
        ge=1, le=10000, description="At rest: physics steps over which the object is observed after settling.")


class ContactSimParams(Section):
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
