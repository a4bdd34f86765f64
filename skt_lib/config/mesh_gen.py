"""``mesh_gen``: procedural supports and objects."""

from pydantic import Field, model_validator

from skt_lib.config import PositiveLength, Section, check_range


class MeshGenParams(Section):
    n_supports: int = Field(ge=4, le=5000, description="Supporting items the train/val/test split is drawn from.")
    n_extra_train_supports: int = Field(
        default=0, ge=0, le=5000,
        description="Further supporting items, generated after the n_supports and all training: "
                    "more training data with the same validation and test supports.")
    n_val_per_level: int = Field(ge=0, description="Validation supports per difficulty level.")
    n_test_per_level: int = Field(ge=1, description="Test supports per difficulty level.")
    n_objects_per_category: int = Field(ge=2, le=100, description="Objects per category.")
    n_test_objects_per_category: int = Field(
        ge=1, le=99, description="Test objects per category (never used to make labels); the rest train."
    )
    support_radius_m: tuple[PositiveLength, PositiveLength] = Field(
        description="Range of the support tube's section half-width (round radius / square half-side)."
    )
    object_rod_radius_m: PositiveLength = Field(
        description="Every object's aperture admits a rod of at least this radius."
    )
    level_rise_m: tuple[PositiveLength, PositiveLength, PositiveLength] = Field(
        description="Blocking-height thresholds between easy|normal|hard|very_hard."
    )
    narrow_gap_m: PositiveLength = Field(
        description="Clearance above the hanging arm below which a support is one level harder."
    )
    curl_very_hard_deg: float = Field(
        gt=90.0, lt=360.0, description="Total tip turning above which a hook is very_hard."
    )
    density_kg_m3: float = Field(gt=10.0, lt=20000.0, description="Object material density.")

    @model_validator(mode="after")
    def _consistent(self) -> "MeshGenParams":
        check_range("support_radius_m", self.support_radius_m)
        if not self.level_rise_m[0] < self.level_rise_m[1] < self.level_rise_m[2]:
            raise ValueError("level_rise_m: thresholds must increase strictly")
        if self.support_radius_m[1] >= self.object_rod_radius_m:
            raise ValueError(
                "support_radius_m: the thickest support must be thinner than object_rod_radius_m"
            )
        if self.n_test_objects_per_category >= self.n_objects_per_category:
            raise ValueError(
                f"n_test_objects_per_category: {self.n_test_objects_per_category} leaves no training "
                f"objects of {self.n_objects_per_category} per category"
            )
        n_fixed = 4 * (self.n_val_per_level + self.n_test_per_level)
        if n_fixed >= self.n_supports:
            raise ValueError(
                f"n_supports: {self.n_supports} leaves no training supports after "
                f"{n_fixed} val+test supports"
            )
        return self
