"""Rerun recordings written by ``skt`` (entity tree of :mod:`viz.rerun_log`)."""

from pathlib import Path

import numpy as np

from viz.rerun_log import affordance_colors, log_colored_points, log_points, log_strip, recording

_USER = "world/supports/user"


def log_prediction(path: Path, pred, references: dict[str, np.ndarray]) -> None:
    """The cloud coloured by affordance, the contact point, the SKT (support frame) and, in
    grey, ``references``: SCTDN's family template (``template``), or skt_flow's other samples
    (``samples/1`` …, clearest first); written atomically."""
    with recording("skt_predict", path, "skt predict") as rec:
        log_colored_points(rec, f"{_USER}/cloud", pred.points,
                           affordance_colors(pred.skt.affordance), static=True)
        log_points(rec, f"{_USER}/contact", [pred.skt.contact], labels=["contact"], static=True)
        for name, positions in references.items():
            log_strip(rec, f"{_USER}/{name}", positions, rgb=(150, 150, 150), static=True)
        log_strip(rec, f"{_USER}/skt", pred.skt.positions, static=True)


def log_hang(path: Path, task, result: dict, support, obj, robot_base) -> None:
    """The rollout of one ``skt hang`` trial (``viz.rollouts`` layout), written atomically."""
    from skt_lib.geometry.export import read_obj
    from viz.rollouts import log_rollouts

    log_rollouts(path, [(task, result)], {support.support_id: read_obj(support.mesh)[0]},
                 {obj.object_id: read_obj(obj.mesh)[0]}, robot_base)
