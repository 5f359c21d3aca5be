"""Exports: an annotation set and the reconstruction under it, written in one of the formats that leave the
system (CAMA's release layout, MapTR vectors, a nuScenes-CAMAv2 root, Lanelet2), with refined poses by default.

The format writers are pure functions of `annotations` (the lowest layer); this package resolves what they
need (the data set, the workspace's refined poses, the site's scenes), stages the whole export beside its final
name and renames it into place only when every file is written (`staging`), so a half-written export never
appears. `cama export` (cama_studio) and the editor's export job (app.backend) are both thin callers of
`export`.
"""

from cama_pipeline.export.request import (
    CamaMode,
    ExportFormat,
    ExportRequest,
    ExportResult,
    PoseChoice,
)
from cama_pipeline.export.run import export

__all__ = ["CamaMode", "ExportFormat", "ExportRequest", "ExportResult", "PoseChoice", "export"]
