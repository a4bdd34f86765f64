"""``train``: SCTDN and the training loop the baselines share."""

from pydantic import Field

from skt_lib.config import Section


class TrainParams(Section):
    epochs: int = Field(ge=1, le=10000, description="Training epochs.")
    views_per_epoch: int = Field(ge=1, le=1000, description="Random views per training support per epoch.")
    batch_size: int = Field(ge=1, le=1024, description="Clouds per step.")
    lr: float = Field(gt=0.0, le=1.0, description="Adam learning rate at the first epoch.")
    lr_final_ratio: float = Field(gt=0.0, le=1.0, description="Cosine decay: the last epoch's learning rate is lr × this.")
    weight_decay: float = Field(ge=0.0, le=1.0, description="Adam weight decay.")
    val_views: tuple[int, ...] = Field(min_length=1, description="Views of each val support evaluated.")
    centres: tuple[int, int, int] = Field(description="PointNet++ set-abstraction centres per level (paper: 512, 256, 64 and a fourth of 16).")
    nsample: int = Field(ge=1, le=128, description="Neighbours grouped per set-abstraction centre (paper: 32).")
    feat_dim: int = Field(ge=8, le=1024, description="Per-point feature width (affordance head and shape feature).")
    lstm_hidden: int = Field(ge=8, le=1024, description="Deformation LSTM hidden width (paper: 256).")
    contact_weight: float = Field(ge=0.0, le=100.0, description="Weight of the contact cross-entropy L_p (not in the paper; 0 switches it off).")
    hang_taper_waypoints: int = Field(ge=0, le=1000, description="Waypoints over which the deformation fades in from the hang: offset i is scaled by min(1, i / this), so ξ_0 stays where the template puts it, release_lift_m above the predicted contact (not in the paper; 0: deform every waypoint; must be < clustering.T).")
    check_families: int = Field(ge=0, le=100, description="SCTDN read-out (not in the paper): 0 returns the classifier's family, deformed; n ≥ 1 offers the deformed SKT and the aligned template of each of the n most probable families and returns the one whose reference ring cuts least into the input cloud (skt_lib.learning.cloud_check; must be ≤ clustering.k).")
    threads: int = Field(ge=1, le=256, description="Torch CPU threads while training (fixed, not the core count: float sums depend on it, so the same value gives the same weights on any machine).")
