"""``affordance_maps``: contact and segmentation maps per view."""

from pydantic import Field

from skt_lib.config import Section


class AffordanceMapsParams(Section):
    sigma_m: float = Field(gt=0.0, le=0.05, description="Gaussian width of both maps (paper: 0.005).")
    alpha: float = Field(ge=0.0, le=1.0, description="Weight of the contact map.")
    beta: float = Field(ge=0.0, le=1.0, description="Weight of the segmentation map.")
    hanging_part_m: float = Field(gt=0.0, le=0.2, description="SKT arc length from ξ_0 that is the hanging part.")
    visible_tol_m: float = Field(gt=0.0, le=0.05, description="Contact visible if a cloud point is this close.")
