"""The CAMA names other modules import from one place: the `map_labels.json` model and type table
(`annotations.cama_labels`), the version 1 sidecar model (`annotations.cama_sidecar`) and import of every CAMA
layout (`annotations.cama_import.import_cama`).

Exports write CAMA's public release layout (`annotations.cama_release.export_cama_release`). The older
folder-per-site layout (sidecar version 1: `maps/map_labels.json` in the pixels of the stored raster,
`maps/georeference.json`, `maps/elevation.npy`) is no longer written; `import_cama` still reads it, since such
exports exist on users' disks.
"""

from annotations.cama_import import (
    DEFAULT_RELEASE_RESOLUTION_M,
    ELEVATION,
    IMPORT_AUTHOR,
    import_cama,
    release_elevation_path,
)
from annotations.cama_labels import (
    CAMA_TYPE_FROM_CLASS,
    CLASS_FROM_CAMA_TYPE,
    MAP_LABELS,
    CamaAttrs,
    CamaInstance,
    CamaMapLabels,
    CamaType,
    class_from_cama_type,
    format_validation_error,
    read_json_file,
    validate_file,
)
from annotations.cama_sidecar import CamaGeoreferenceFile

__all__ = [
    "CAMA_TYPE_FROM_CLASS",
    "CLASS_FROM_CAMA_TYPE",
    "DEFAULT_RELEASE_RESOLUTION_M",
    "ELEVATION",
    "IMPORT_AUTHOR",
    "MAP_LABELS",
    "CamaAttrs",
    "CamaGeoreferenceFile",
    "CamaInstance",
    "CamaMapLabels",
    "CamaType",
    "class_from_cama_type",
    "format_validation_error",
    "import_cama",
    "read_json_file",
    "release_elevation_path",
    "validate_file",
]
