"""Training labels: affordance maps and SKT template families."""
