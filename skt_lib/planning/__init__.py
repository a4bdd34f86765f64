"""Motion planning of the reference object (OMPL RRT-Connect) and SKT post-processing."""
