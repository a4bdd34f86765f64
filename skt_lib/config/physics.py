"""The evaluation's object damping (``sim_eval``), by which ``contact_sim`` also judges a
support's hang: the ground truth must pass the evaluation's physics."""

from typing import Annotated

from pydantic import Field

from skt_lib.config import Partial

Damping = Annotated[float, Field(ge=0.0, le=10.0)]
LinearDamping = Annotated[Damping, Field(description="Object linear damping (1/s) while carried, released and perturbed; PyBullet's default 0.04, as the anchors' (docs/design.md#the-success-predicate).")]
AngularDamping = Annotated[Damping, Field(description="Object angular damping (1/s) while carried, released and perturbed; PyBullet's default 0.04.")]
SettleLinearDamping = Annotated[Damping, Field(description="Object linear damping during the final settle only (an undamped hung object keeps swinging).")]
SettleAngularDamping = Annotated[Damping, Field(description="Object angular damping during the final settle only.")]


class DampingOnly(Partial):
    """``sim_eval``'s four object damping rates alone."""

    linear_damping: LinearDamping
    angular_damping: AngularDamping
    settle_linear_damping: SettleLinearDamping
    settle_angular_damping: SettleAngularDamping
