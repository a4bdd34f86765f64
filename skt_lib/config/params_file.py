"""The whole ``params.yaml`` validated at once: every section, no unknown one, and the
checks across sections. For tools, the CLI and tests; a stage loads only its own sections
(:func:`skt_lib.config.load_sections`)."""

from pathlib import Path

from pydantic import ValidationError, model_validator

from skt_lib.config import CommonParams, ComputeParams, Section, format_error, read_params
from skt_lib.config.affordance_maps import AffordanceMapsParams
from skt_lib.config.clustering import ClusteringParams
from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.config.render_views import RenderViewsParams
from skt_lib.config.rotation_extraction import RotationExtractionParams
from skt_lib.config.rrt_skts import RrtSktsParams
from skt_lib.config.sim_eval import SimEvalParams
from skt_lib.config.train import TrainParams
from skt_lib.config.train_baselines import BASELINE_MODELS, TrainBaselinesParams
from skt_lib.errors import ParamsError


class Params(Section):
    common: CommonParams
    compute: ComputeParams
    mesh_gen: MeshGenParams
    contact_sim: ContactSimParams
    rotation_extraction: RotationExtractionParams
    rrt_skts: RrtSktsParams
    render_views: RenderViewsParams
    affordance_maps: AffordanceMapsParams
    clustering: ClusteringParams
    train: TrainParams
    train_baselines: TrainBaselinesParams
    sim_eval: SimEvalParams

    @model_validator(mode="after")
    def _baselines_trained(self) -> "Params":
        untrained = [m for m in self.sim_eval.methods
                     if m in BASELINE_MODELS and m not in self.train_baselines.models]
        if untrained:
            raise ValueError(f"sim_eval.methods: {untrained} evaluated but not trained (add them "
                             "to train_baselines.models)")
        return self


def parse_params(data: object, source: str = "params") -> Params:
    """Validate a params mapping; raise :class:`ParamsError` naming every bad key."""
    if not isinstance(data, dict):
        raise ParamsError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
    try:
        return Params.model_validate(data)
    except ValidationError as err:
        raise ParamsError(format_error(source, err)) from None


def load_params(path: str | Path = "params.yaml") -> Params:
    """Read and validate the whole ``params.yaml``."""
    return parse_params(read_params(path), str(path))
