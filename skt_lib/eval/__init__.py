"""Evaluation: methods that turn a support cloud into an SKT, and the Table I runner."""
