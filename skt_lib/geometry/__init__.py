"""Procedural shapes as unions of convex parts, their checks and their file formats."""
