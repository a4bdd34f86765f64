"""``clustering.T``, the waypoints an SKT is executed and learned with: read by
``rrt_skts`` (its re-check executes at T) before ``clustering`` runs."""

from typing import Annotated

from pydantic import Field

from skt_lib.config import Partial

Waypoints = Annotated[int, Field(ge=2, le=200, description="Waypoints per SKT (paper: 40; sweep 10/20/40).")]


class WaypointsOnly(Partial):
    """``clustering``'s ``T`` alone."""

    T: Waypoints
