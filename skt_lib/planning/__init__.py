"""Planning SKTs: the threading planner, its probe, the independent re-check, trajectories."""
