"""``train_baselines``: the paper's baselines and skt_flow, trained with ``train``'s loop."""

from typing import Literal

from pydantic import Field, model_validator

from skt_lib.config import Section

BASELINE_MODELS = ("sctdn_cp_feature", "vatmart", "vatmart_mod", "skt_flow")
#: The views a model may learn from (``views``; :data:`skt_lib.learning.data.VIEW_DIRS`).
VIEW_SETS = ("clean", "sensor", "both")


class TrainBaselinesParams(Section):
    models: tuple[Literal[BASELINE_MODELS], ...] = Field(
        description="Baselines trained with train's loop, data and budget: sctdn_cp_feature (Table II ablation: deformation conditioned on the contact-point feature), vatmart (CVAE on the contact-point feature), vatmart_mod (CVAE on the shape-conditioned feature), skt_flow (conditional flow matching over the SKT's control points, its samples ordered by the cloud check).")
    latent_dim: int = Field(ge=1, le=1024, description="VAT-Mart CVAE latent width (paper: 128).")
    hidden: int = Field(ge=8, le=4096, description="VAT-Mart CVAE encoder/decoder MLP width.")
    n_control_points: int = Field(ge=2, le=1000, description="VAT-Mart decoder: control points, linearly interpolated to the clustering.T waypoints (≤ T).")
    vatmart_kl_weight: float = Field(ge=0.0, le=10.0, description="KL weight of vatmart (paper: 0.1).")
    vatmart_mod_kl_weight: float = Field(ge=0.0, le=10.0, description="KL weight of vatmart_mod (paper: 0.01).")
    skt_flow_n_control: int = Field(ge=2, le=1000, description="skt_flow: control points it generates, linearly interpolated to the clustering.T waypoints (≤ T; 12 reproduce the validation SKTs to 0.65 mm mean, 8 to 1.0 mm).")
    skt_flow_steps: int = Field(ge=1, le=1000, description="skt_flow: Euler steps from noise to an SKT.")
    skt_flow_hidden: int = Field(ge=8, le=4096, description="skt_flow: width of its MLP (three hidden layers) that predicts the flow's end point.")
    skt_flow_draws: int = Field(ge=1, le=256, description="skt_flow: (noise, ground-truth SKT, time) draws per cloud per training step (the backbone runs once per cloud).")

    views: dict[Literal[BASELINE_MODELS], Literal[VIEW_SETS]] = Field(
        default_factory=dict, description="The views a model learns from and is selected on (a model not named: clean): clean = render_views' ring, as Table I's views; sensor = its depth-camera views (render_views.sensor_views_severity > 0); both = the two in one pool, each epoch's views drawn from either, selected on the clean validation views.")

    @model_validator(mode="after")
    def _unique(self) -> "TrainBaselinesParams":
        if len(set(self.models)) != len(self.models):
            raise ValueError(f"models: duplicate entries in {list(self.models)}")
        return self
