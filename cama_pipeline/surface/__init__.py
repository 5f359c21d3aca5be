"""Road surface reconstruction (RoMe-style): elevation MLP, optimised mesh, BEV rasters."""

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.stage import run

__all__ = ["SurfaceConfig", "run"]
