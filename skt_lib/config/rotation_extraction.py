"""``rotation_extraction``: keypoint frames from the hangs."""

from pydantic import Field

from skt_lib.config import Section


class RotationExtractionParams(Section):
    front_offset_m: float = Field(gt=0.0, le=0.5, description="How far P_front lies back along the approach.")
