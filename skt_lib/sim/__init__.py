"""PyBullet simulation: worlds, the hanging perturbation and predicate, contact simulation."""
