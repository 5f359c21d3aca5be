"""Road surface reconstruction (RoMe-style): elevation MLP, optimised mesh, BEV rasters."""

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.stage import SiteSurface, run

__all__ = ["SiteSurface", "SurfaceConfig", "run"]
