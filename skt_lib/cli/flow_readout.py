"""``skt_flow`` as ``skt predict``'s model: the one SKT Table I's ``skt_flow`` single-SKT row
runs.

The flow draws ``n_samples`` SKTs from noise, from ``n_contacts`` contact hypotheses in turn,
and orders them by the cloud check (how deep the reference ring, carried along a sample, cuts
into the observed points), the affordance's argmax trusted first
(:func:`skt_lib.eval.contact_hypotheses.propose`); the first, moved clear of those points
as ``sim_eval`` moves it (:func:`skt_lib.eval.clear_shift.shifted`), is the prediction, the
others are its ``fallbacks``, clearest first and as drawn. The noise comes from ``numpy``'s
generator seeded with ``seed`` on every call, so a cloud gives the same SKT each time.
``sim_eval`` draws its noise per support from the run's seed instead
(:func:`skt_lib.seeding.item_rng`), so the CLI's SKT for a test view is another draw of the
same model, not Table I's trial.
"""

from pathlib import Path

import numpy as np

from skt_lib.eval.clear_shift import shifted
from skt_lib.eval.contact_hypotheses import ContactHypotheses, propose
from skt_lib.learning.flow import FlowPredictor
from skt_lib.learning.predictor import Skt

#: Samples drawn per prediction: ``sim_eval.n_proposals``' default, what the single-SKT row's
#: cloud check ranks.
N_SAMPLES = 10
#: Contact hypotheses they start from: ``sim_eval.flow_contacts``' default.
N_CONTACTS = 3


class FlowReadout:
    """One SKT per cloud from a trained ``skt_flow``; ``predict`` as
    :meth:`skt_lib.learning.predictor.SktPredictor.predict` (``family`` is -1: the flow has
    no template families, and ``family_probability`` is NaN)."""

    def __init__(self, flow: FlowPredictor, n_samples: int = N_SAMPLES, seed: int = 0,
                 n_contacts: int = N_CONTACTS):
        if n_samples < 1:
            raise ValueError(f"n_samples: need at least one, got {n_samples}")
        self.flow, self.n_samples, self.seed = flow, n_samples, seed
        self.contacts = ContactHypotheses(n_contacts)
        self.cfg = flow.cfg

    @classmethod
    def load(cls, directory: str | Path, n_samples: int = N_SAMPLES,
             seed: int = 0) -> "FlowReadout":
        return cls(FlowPredictor.load(directory), n_samples, seed)

    def predict(self, points: np.ndarray) -> Skt:
        """The clearest sample by the cloud check, moved clear of ``points``; the others, in
        that order and as drawn, its fallbacks (shown in ``--rrd`` recordings)."""
        first, *others = propose(self.flow, points, np.random.default_rng(self.seed),
                                 self.n_samples, self.contacts)
        first = shifted(first, points)
        return Skt(first.positions, first.frames, first.family, first.contact,
                   first.affordance, fallbacks=tuple(s.positions for s in others))
