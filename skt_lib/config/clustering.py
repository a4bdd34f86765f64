"""``clustering``: the SKT families and their templates."""

from pydantic import Field

from skt_lib.config import Section
from skt_lib.config.waypoints import Waypoints


class ClusteringParams(Section):
    T: Waypoints
    k: int = Field(ge=1, le=50, description="Template families (paper: 5).")
    n_init: int = Field(ge=1, le=100, description="k-means++ restarts.")
    max_iter: int = Field(ge=1, le=10000, description="Lloyd iterations per restart.")
