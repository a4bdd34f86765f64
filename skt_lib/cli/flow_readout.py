"""``skt_flow`` as ``skt predict``'s model: the one SKT Table I's ``skt_flow`` single-SKT row
runs.

The flow draws ``n_samples`` SKTs from noise, from ``n_contacts`` contact hypotheses in turn,
moves each clear of the observed points as ``sim_eval`` moves them
(:func:`skt_lib.eval.clear_shift.shifted`), and orders them by the training objects carried
along them (:mod:`skt_lib.eval.probe_check`; ``probes``, those of the data root the model
was trained in). The first is the prediction, the others are its ``fallbacks``, in that
order. Without probes the order is the cloud check's, as
:func:`skt_lib.eval.contact_hypotheses.propose` gives it. The noise comes from ``numpy``'s
generator seeded with ``seed`` on every call, so a cloud gives the same SKT each time.
``sim_eval`` draws its noise per support from the run's seed instead
(:func:`skt_lib.seeding.item_rng`), so the CLI's SKT for a test view is another draw of the
same model, not Table I's trial.
"""

from pathlib import Path

import numpy as np

from skt_lib.eval.clear_shift import shifted
from skt_lib.eval.contact_hypotheses import ContactHypotheses, propose
from skt_lib.eval.probe_check import ProbeSet, ordered
from skt_lib.learning.flow import FlowPredictor
from skt_lib.learning.predictor import Skt

#: Samples drawn per prediction: ``sim_eval.flow_samples``' default, what the single-SKT
#: row's read-out orders.
N_SAMPLES = 30
#: Contact hypotheses they start from: ``sim_eval.flow_contacts``' default.
N_CONTACTS = 3


class FlowReadout:
    """One SKT per cloud from a trained ``skt_flow``; ``predict`` as
    :meth:`skt_lib.learning.predictor.SktPredictor.predict` (``family`` is -1: the flow has
    no template families, and ``family_probability`` is NaN)."""

    def __init__(self, flow: FlowPredictor, n_samples: int = N_SAMPLES, seed: int = 0,
                 n_contacts: int = N_CONTACTS, probes: ProbeSet | None = None):
        if n_samples < 1:
            raise ValueError(f"n_samples: need at least one, got {n_samples}")
        self.flow, self.n_samples, self.seed, self.probes = flow, n_samples, seed, probes
        self.contacts = ContactHypotheses(n_contacts)
        self.cfg = flow.cfg

    @classmethod
    def load(cls, directory: str | Path, n_samples: int = N_SAMPLES, seed: int = 0,
             probes: ProbeSet | None = None) -> "FlowReadout":
        return cls(FlowPredictor.load(directory), n_samples, seed, probes=probes)

    def predict(self, points: np.ndarray) -> Skt:
        """Every sample moved clear of ``points``; the first by the probes' order (without
        probes: the cloud check's, as drawn), the others, in that order, its fallbacks
        (shown in ``--rrd`` recordings)."""
        skts = [shifted(k, points) for k in propose(
            self.flow, points, np.random.default_rng(self.seed), self.n_samples, self.contacts)]
        if self.probes is not None:
            skts = ordered(skts, points, self.probes)
        first, *others = skts
        return Skt(first.positions, first.frames, first.family, first.contact,
                   first.affordance, fallbacks=tuple(s.positions for s in others))
