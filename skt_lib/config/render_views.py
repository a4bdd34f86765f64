"""``render_views``: the partial point clouds of every support."""

from pydantic import Field, model_validator

from skt_lib.config import Section, check_range


class RenderViewsParams(Section):
    n_azimuth: int = Field(ge=1, le=64, description="Camera azimuths (n_azimuth × n_elevation views).")
    n_elevation: int = Field(ge=1, le=64, description="Camera elevations.")
    azimuth_deg: tuple[float, float] = Field(description="Azimuth span; 0 = in front (+x).")
    elevation_deg: tuple[float, float] = Field(description="Elevation span; positive = above.")
    distance_m: float = Field(gt=0.05, le=3.0, description="Camera distance from the support's centre.")
    fov_deg: float = Field(gt=5.0, lt=170.0, description="Vertical field of view.")
    width: int = Field(ge=16, le=4096, description="Image width, pixels.")
    height: int = Field(ge=16, le=4096, description="Image height, pixels.")
    n_points: int = Field(ge=16, le=100000, description="Points per view after farthest-point sampling.")
    noise_std_m: float = Field(ge=0.0, le=0.01, description="Depth noise along the ray; 0 = off.")
    sensor_severity: float = Field(0.0, ge=0.0, le=4.0, description="Depth-camera views (skt_lib/perception/camera_views.py): the wall in view, the sensor model of skt_lib/perception/sensor.py at this severity (1 = a structured-light / stereo camera's defaults), the support frame found from the wall as `skt predict --camera` finds it; 0 = a perfect ray cast of the support alone.")
    sensor_views_severity: float = Field(0.0, ge=0.0, le=4.0, description="> 0: also depth-camera views (as sensor_severity > 0 makes them) of the training and validation supports at this severity, in data/render_views/sensor/, for the models train_baselines.views trains on them; 0 = none. Table I's views stay those of sensor_severity.")

    @model_validator(mode="after")
    def _ranges(self) -> "RenderViewsParams":
        check_range("azimuth_deg", self.azimuth_deg)
        check_range("elevation_deg", self.elevation_deg)
        if not -90 < self.elevation_deg[0] and self.elevation_deg[1] < 90:
            raise ValueError("elevation_deg: must lie strictly between -90 and 90")
        if not -90 <= self.azimuth_deg[0] and self.azimuth_deg[1] <= 90:
            raise ValueError("azimuth_deg: cameras must stay in front of the wall (|az| <= 90)")
        return self
