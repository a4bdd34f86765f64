"""Partial point clouds of supporting items: cameras, depth rendering, farthest-point sampling."""
