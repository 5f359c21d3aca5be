"""The poses an export writes: refined ones from the workspace (default) or the data set's logged ones when
asked for, and the site (and its scenes) they belong to."""

from dataclasses import dataclass

from annotations.poses import PoseLookup, coarse_pose
from cama_pipeline.data import Dataset
from cama_pipeline.export.request import PoseChoice
from cama_pipeline.refined_poses import refined_pose_lookup, refined_poses, site_scenes
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.workspace import Workspace


@dataclass(frozen=True)
class ExportPoses:
    """The pose lookup of an export and the scenes and site it covers."""

    lookup: PoseLookup
    scenes: tuple[str, ...]
    """The site's scenes (refined poses), or every scene of the data set (coarse poses, no site)."""
    site_id: str | None
    """The site whose reconstruction gave the poses (None for coarse poses without a workspace site)."""


def export_site_id(workspace: Workspace, annotation_site_id: str, site_id: str | None) -> str:
    """The site whose reconstruction gives the poses: `site_id`, else the annotation set's site when the
    workspace has it, else the workspace's only site; ValueError / FileNotFoundError saying what to pass."""
    index = workspace.sites_index()
    if not index.is_file():
        raise FileNotFoundError(f"{index}: missing; run `cama sites` .. `cama sfm`, or pass --poses coarse")
    sites = read_site_ids(index)
    if site_id is not None:
        if site_id not in sites:
            raise ValueError(f"--site-id {site_id!r}: not a site of {index} (sites: {sites})")
        return site_id
    if annotation_site_id in sites:
        return annotation_site_id
    if len(sites) == 1:
        return sites[0]
    raise ValueError(
        f"{index}: sites {sites}; pass --site-id (the annotation set's is {annotation_site_id!r})"
    )


def export_poses(
    choice: PoseChoice, data: Dataset, workspace: Workspace, annotation_site_id: str, site_id: str | None
) -> ExportPoses:
    """The export's poses: refined from the site's SfM outputs (FileNotFoundError naming the missing one and
    what to run), or the logged ones when `choice` is coarse (the site's scenes when the workspace has the site,
    else every scene)."""
    if choice is PoseChoice.coarse:
        scenes = tuple(scene.name for scene in data.scenes)
        if workspace.sites_index().is_file():
            site = export_site_id(workspace, annotation_site_id, site_id)
            return ExportPoses(coarse_pose, tuple(site_scenes(workspace, site)), site)
        return ExportPoses(coarse_pose, scenes, None)
    site = export_site_id(workspace, annotation_site_id, site_id)
    try:
        poses = refined_poses(data, workspace, site)
    except FileNotFoundError as error:
        raise FileNotFoundError(
            f"refined poses need the SfM outputs: {error}; run `cama sfm` first, or pass --poses coarse"
        ) from error
    scenes = tuple(
        scene.name for scene in data.scenes if any(image.token in poses for image in scene.all_images())
    )
    return ExportPoses(refined_pose_lookup(poses), scenes, site)
