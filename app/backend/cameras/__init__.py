"""The camera panel's machinery, pure (no FastAPI): a site's camera context, view selection, projection of
elements into images, and the images and lane-mask overlays themselves.

Coordinates: site metres are global minus the site origin in x and y, z global (the elevation raster's).
Pixels are full-resolution [u = column, v = row], pixel centres at integers.

Stable API (other backend modules, e.g. the per-element reprojection figures, import these):

- `SiteSources(site_id, georeference, raster_dir, dataset_root=None, workspace_dir=None, recon_site_id=None)`:
  where a site's cameras come from (its registration, plain values).
- `ContextCache().get(sources) -> CameraContext`: loaded once per site, reloaded when the sources or the files
  read (data set tables, SfM poses, WIGO files, site manifest, elevation, mask manifests) change.
  `load_context(sources)` reads one without caching.
- `CameraContext`: `.dataset` (Dataset | None), `.views` (tuple of `PosedView`: key-frame images with an SfM
  pose; `.token`, `.scene`, `.channel`, `.timestamp_us`, `.image` (CameraImage, with its instance mask path),
  `.global_from_ego` (Pose), `.pose_source`, `.camera` (PinholeCamera, global), `.width`, `.height`),
  `.by_token`, `.poses` (every refined pose by token), `.elevation`, `.images`, `.mask_source`, `.notice`
  (why there are no views, else None), `.available`, `.poses_digest` (changes with the posed views' poses),
  `.site_origin_xy`.
- `best_views(context, element_points_site_2d, n, all_=False) -> list[ViewChoice]`: the n best views of an
  element (2D site polyline), spread along it, in station order; every candidate with `all_`.
  `best_views_for_point(context, (x, y), n, all_=False)` for a site point. `ViewChoice`: token, channel,
  scene, timestamp_us, width, height, score, distance_m, obliqueness_deg, station_m.
- `lift_site_points(context, points_site_2d) -> LiftedElement` (`.points_3d` (N, 3) site metres, densified,
  `.station_m`, `.notice`); `select(context, lifted, n, all_=False)` selects views of an already lifted element.
- `image_camera(context, token) -> ImageCamera` (`.camera` PinholeCamera in global metres, `.pose_source`;
  ImageNotFound for an image without a refined pose); `cam_from_site(camera, site_origin_xy) -> (4, 4)`.
- `project_site_polyline(context, camera, points_3d_site) -> list[(M, 2) pixel arrays]`;
  `project_neighbours(context, camera, [(id, cls, points_2d), ...]) -> list[ProjectedNeighbour]`.
- `image_file(context, token)`, `lane_mask_file(context, token)`: resolved files, only from the data set's tables
  and inside its root (or mask roots); `ImageNotFound` / `PathEscape` otherwise. `ImageCache().get(kind, path,
  width)` encodes and caches (`image`: JPEG scaled with INTER_AREA, `lane-mask`: RGBA PNG overlay).
"""

from app.backend.cameras.context import (
    NO_RECONSTRUCTION,
    CameraContext,
    ContextCache,
    PosedView,
    SiteSources,
    load_context,
)
from app.backend.cameras.images import (
    NO_LANE_MASK,
    TOKEN_PATTERN,
    WIDTHS,
    Encoded,
    ImageCache,
    PathEscape,
    image_file,
    lane_mask_file,
)
from app.backend.cameras.projection import (
    ImageCamera,
    ImageNotFound,
    ProjectedNeighbour,
    cam_from_site,
    image_camera,
    project_neighbours,
    project_site_polyline,
)
from app.backend.cameras.views import (
    LiftedElement,
    ViewChoice,
    best_views,
    best_views_for_point,
    lift_site_point,
    lift_site_points,
    select,
)

__all__ = [
    "NO_LANE_MASK",
    "NO_RECONSTRUCTION",
    "TOKEN_PATTERN",
    "WIDTHS",
    "CameraContext",
    "ContextCache",
    "Encoded",
    "ImageCache",
    "ImageCamera",
    "ImageNotFound",
    "LiftedElement",
    "PathEscape",
    "PosedView",
    "ProjectedNeighbour",
    "SiteSources",
    "ViewChoice",
    "best_views",
    "best_views_for_point",
    "cam_from_site",
    "image_camera",
    "image_file",
    "lane_mask_file",
    "lift_site_point",
    "lift_site_points",
    "load_context",
    "project_neighbours",
    "project_site_polyline",
    "select",
]
