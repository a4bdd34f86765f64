"""``sim_eval.n_proposals``: how many SKTs a proposing method offers per support, which
``train_baselines`` also uses (the validation of the proposing models)."""

from typing import Annotated

from pydantic import Field

from skt_lib.config import Partial

Proposals = Annotated[int, Field(ge=1, le=100, description="Proposing methods (vatmart, vatmart_mod, skt_flow): proposals per support; a (support, object) trial succeeds if any proposal hangs (the paper's count); success_single counts the first proposal only (skt_flow's: the sample its cloud check ranks first).")]


class ProposalsOnly(Partial):
    """``sim_eval``'s ``n_proposals`` alone."""

    n_proposals: Proposals
