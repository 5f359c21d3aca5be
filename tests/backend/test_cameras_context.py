"""The camera panel's pure machinery (`app.backend.cameras`, `crud.site_sources`): where a registration's cameras
come from, the per-site context cached until a file it was read from changes, the image cache's bound and the
lane-mask overlay's colours."""

import os
import shutil
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from annotations.schema import AnnotationSet, Georeference
from app.backend.cameras import NO_RECONSTRUCTION, ContextCache, ImageCache, SiteSources, best_views
from app.backend.cameras.images import MASK_ALPHA, lane_overlay_png
from app.backend.cameras.views import ViewChoice, spread
from app.backend.crud.site_sources import camera_sources
from app.backend.schemas import SiteCreate
from cama_pipeline.bev import read_georeference
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite


def reconstruction(whole_path: PipelineResult) -> tuple[str, Path, AnnotationSet]:
    """The reconstruction's site id, surface rasters and proposals."""
    site, proposals = sorted(whole_path.proposals.items())[0]
    return site, Workspace(whole_path.workspace).surface_bev(site), AnnotationSet.read_json(proposals)


def test_camera_sources_of_a_surface_raster_folder_and_of_a_synthetic_site(
    whole_path: PipelineResult, tiny_site: GeneratedSite
) -> None:
    site, bev, _ = reconstruction(whole_path)
    workspace, synthetic = whole_path.workspace.resolve(), tiny_site.result.out_dir.resolve()
    request = SiteCreate(name="s", synthetic_dir=str(synthetic))
    found = camera_sources(request, raster_dir=bev, synthetic_dir=None, roots=[workspace])
    assert (found.dataset_root, found.workspace_dir, found.recon_site_id) == (None, workspace, site)
    outside = camera_sources(request, raster_dir=bev, synthetic_dir=None, roots=[bev])
    assert (outside.workspace_dir, outside.recon_site_id) == (
        None,
        None,
    )  # the workspace is outside the roots
    synthetic_found = camera_sources(
        request, raster_dir=bev, synthetic_dir=synthetic, roots=[workspace, synthetic]
    )
    assert synthetic_found.dataset_root == synthetic / "nuscenes"
    given = replace_request(request, dataset_root=str(synthetic / "nuscenes"), workspace_dir=str(workspace))
    both = camera_sources(given, raster_dir=synthetic, synthetic_dir=None, roots=[workspace, synthetic])
    assert (both.dataset_root, both.workspace_dir, both.recon_site_id) == (
        synthetic / "nuscenes",
        workspace,
        site,
    )


def replace_request(request: SiteCreate, **fields: str) -> SiteCreate:
    return request.model_copy(update=fields)


def test_the_context_is_kept_until_a_file_it_was_read_from_changes(
    whole_path: PipelineResult, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    site, bev, proposals = reconstruction(whole_path)
    rasters = tmp_path / "bev"
    shutil.copytree(bev, rasters)
    georeference = Georeference.of(
        read_georeference(bev), site_origin_xy=proposals.georeference.site_origin_xy
    )
    sources = SiteSources(
        1, georeference, rasters, tiny_site.result.out_dir / "nuscenes", whole_path.workspace, site
    )
    cache = ContextCache()
    first = cache.get(sources)
    assert first.available and first.notice is None and cache.get(sources) is first
    elevation = rasters / "elevation.npy"
    stat = elevation.stat()
    os.utime(elevation, ns=(stat.st_atime_ns, stat.st_mtime_ns + 2_000_000_000))
    second = cache.get(sources)
    assert second is not first and second.poses_digest == first.poses_digest
    views = best_views(second, proposals.elements[0].points_2d, 4, all_=True)
    assert views == best_views(first, proposals.elements[0].points_2d, 4, all_=True)
    without = cache.get(replace(sources, recon_site_id=None))
    assert without.notice == NO_RECONSTRUCTION and not without.available and without.views == ()
    assert best_views(without, proposals.elements[0].points_2d, 4) == []


def test_the_image_cache_keeps_within_its_budget(tmp_path: Path) -> None:
    paths = []
    for index in range(4):
        path = tmp_path / f"{index}.jpg"
        noise = np.random.default_rng(index).integers(0, 255, (120, 200, 3), dtype=np.uint8)
        cv2.imwrite(str(path), noise)
        paths.append(path)
    cache = ImageCache(max_bytes=2 * paths[0].stat().st_size)
    for path in paths:
        encoded = cache.get("image", path, None)
        assert encoded.data == path.read_bytes() and encoded.media_type == "image/jpeg"
    assert cache.size <= cache.max_bytes and 1 <= len(cache.entries) < 4
    scaled = cache.get("image", paths[0], 120)
    assert np.asarray(cv2.imdecode(np.frombuffer(scaled.data, np.uint8), cv2.IMREAD_COLOR)).shape == (
        72,
        120,
        3,
    )
    assert scaled.etag != cache.get("image", paths[0], None).etag


def test_the_lane_overlay_gives_each_instance_its_own_colour(tmp_path: Path) -> None:
    mask = np.zeros((40, 80), np.uint16)
    mask[5:15, 10:30] = 1001
    mask[20:30, 10:30] = 1002
    mask[20:30, 50:70] = 3001
    path = tmp_path / "mask.png"
    cv2.imwrite(str(path), mask)
    overlay = np.asarray(
        cv2.imdecode(np.frombuffer(lane_overlay_png(path, 40), np.uint8), cv2.IMREAD_UNCHANGED)
    )
    assert overlay.shape == (20, 40, 4)
    assert set(np.unique(overlay[..., 3]).tolist()) == {0, MASK_ALPHA}
    colours = {tuple(overlay[row, col, :3].tolist()) for row, col in ((5, 10), (12, 10), (12, 30))}
    assert len(colours) == 3 and (0, 0, 0) not in colours
    assert (overlay[0, 0] == 0).all()


def _view(token: str, channel: str, station_m: float, centre_x: float, score: float) -> ViewChoice:
    return ViewChoice(token, channel, "scene", 0, 512, 288, score, 10.0, 5.0, station_m, (centre_x, 0.0))


def test_views_from_the_same_spot_are_not_shown_twice() -> None:
    """A parked car's frames of one camera (same spot, best scores) give one view; the next is another viewpoint,
    even with a lower score; another camera at the same spot is a new viewpoint."""
    parked = [_view(f"p{k}", "CAM_BACK", 5.0, 100.0 + 0.1 * k, 0.9) for k in range(3)]
    moving = _view("m", "CAM_BACK", 5.0, 108.0, 0.5)
    side = _view("s", "CAM_BACK_LEFT", 5.0, 100.0, 0.4)
    chosen = spread([*parked, moving, side], 3, 10.0)
    assert sorted(c.token for c in chosen) == ["m", "p0", "s"]
