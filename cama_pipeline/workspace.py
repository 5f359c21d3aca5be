"""Where every stage's files are in a workspace: the only module that joins workspace path pieces.

Default location: `<data set root's parent>/workspace/` (for `data/synthetic/default/nuscenes` that is
`data/synthetic/default/workspace/`), beside the data set, never inside it. The layout, with the module that
owns (reads and writes, and documents) each file's format:

    wigo/<scene>.json                  fused ego poses of one scene                  cama_pipeline.wigo.io
    keyframes/<scene>.json             resynchronised frames and keyframes           cama_pipeline.keyframes.io
    masks/<source>/semantic/<image path>.png       image masks made for a data set without   cama_pipeline.segment.io
    masks/<source>/lane_instance/<image path>.png  its own (<source>: predicted, imported);
    masks/<source>/manifest.json                   the data set's layout under each source
    sites/index.json                   the aggregation's decisions                   cama_pipeline.site.io
    sites/<site_id>/manifest.json      what a site's reconstruction reads            cama_pipeline.site.io
    pairs/<site_id>/pairs.txt          the pair list COLMAP imports                  cama_pipeline.pairs.io
    pairs/<site_id>/pairs.json         the pairs with their reasons, and counts      cama_pipeline.pairs.io
    features/<site_id>/database.db     COLMAP database (features, matches)           cama_pipeline.features.database
    features/<site_id>/features.json   the features stage's report                   cama_pipeline.features.io
    sfm/<site_id>/model/               the merged site model (COLMAP binary)         cama_pipeline.sfm.io
    sfm/<site_id>/clips/<scene>/       each clip's own model                         cama_pipeline.sfm.io
    sfm/<site_id>/poses.json           refined ego poses                             cama_pipeline.sfm.io
    sfm/<site_id>/points.npz           sparse points with labels                     cama_pipeline.sfm.io
    sfm/<site_id>/report.json          the SfM stage's report                        cama_pipeline.sfm.io
    surface/<site_id>/bev/             BEV rasters                                   cama_pipeline.surface.outputs
    surface/<site_id>/mesh.ply         the observed road mesh                        cama_pipeline.surface.outputs
    surface/<site_id>/report.json      the surface stage's report                    cama_pipeline.surface.outputs
    proposals/<site_id>.json           VMA proposals on the site's rasters           models.vma.propose
                                       (+ proposals/<site_id>.json.fingerprint: see cama_pipeline.fingerprints)
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

WORKSPACE_DIRNAME = "workspace"
MASK_SOURCES: tuple[str, ...] = ("predicted", "imported")
"""The workspace's mask roots: masks the segmenter predicted, masks imported from another network."""
"""The default workspace's folder name, beside the data set root."""

StageFolder = Literal[
    "wigo", "keyframes", "masks", "sites", "pairs", "features", "sfm", "surface", "proposals"
]
STAGE_FOLDERS: tuple[StageFolder, ...] = (
    "wigo",
    "keyframes",
    "masks",
    "sites",
    "pairs",
    "features",
    "sfm",
    "surface",
    "proposals",
)
"""The workspace's top-level folders, one per stage that writes into it."""


class SiteLocation(NamedTuple):
    """A site of a workspace, as found from one of its files by `Workspace.locate`."""

    workspace: "Workspace"
    site_id: str


@dataclass(frozen=True)
class Workspace:
    """A workspace folder: one method per stage output (see the module docstring for the layout)."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @classmethod
    def for_dataset(cls, dataset_root: Path) -> "Workspace":
        """`<dataset_root's parent>/workspace`: beside the data set, never inside it."""
        return cls(Path(dataset_root).absolute().parent / WORKSPACE_DIRNAME)

    @classmethod
    def resolve(cls, workspace: "Path | Workspace | None", dataset_root: Path) -> "Workspace":
        """The given workspace (a folder or a Workspace), else the data set's default one (`for_dataset`)."""
        if isinstance(workspace, Workspace):
            return workspace
        return cls(workspace) if workspace is not None else cls.for_dataset(dataset_root)

    @classmethod
    def locate(cls, bev: Path) -> SiteLocation:
        """The workspace and site of a surface stage's raster folder `<workspace>/surface/<site_id>/bev`;
        ValueError naming `bev` when the path is not one (the path is read, the disk is not)."""
        bev = Path(bev)
        site = bev.parent
        if bev.name != "bev" or site.parent.name != "surface" or site.name in ("", ".", ".."):
            raise ValueError(
                f"{bev}: not a surface stage's raster folder (<workspace>/surface/<site_id>/bev)"
            )
        return SiteLocation(cls(site.parent.parent), site.name)

    def stage_dir(self, stage: StageFolder) -> Path:
        """`<root>/<stage>/`: everything one stage wrote."""
        if stage not in STAGE_FOLDERS:
            raise ValueError(f"stage must be one of {', '.join(STAGE_FOLDERS)}, got {stage!r}")
        return self.root / stage

    # -- per scene --------------------------------------------------------------------------------------------

    def wigo(self, scene: str) -> Path:
        """`wigo/<scene>.json`."""
        return self.stage_dir("wigo") / f"{scene}.json"

    def wigo_scenes(self) -> list[str]:
        """The scenes WIGO wrote poses for, sorted (none before `cama wigo`)."""
        return sorted(p.stem for p in self.stage_dir("wigo").glob("*.json"))

    def keyframes(self, scene: str) -> Path:
        """`keyframes/<scene>.json`."""
        return self.stage_dir("keyframes") / f"{scene}.json"

    # -- image masks ------------------------------------------------------------------------------------------

    def masks_dir(self, source: str) -> Path:
        """`masks/<source>/`: a mask root laid out as a data set's (`semantic/`, `lane_instance/` under it, see
        `cama_pipeline.data.schema.mask_relpath`); `source` is `predicted` (`cama segment`) or `imported`
        (`cama import-masks`)."""
        if source not in MASK_SOURCES:
            raise ValueError(f"mask source must be one of {', '.join(MASK_SOURCES)}, got {source!r}")
        return self.stage_dir("masks") / source

    def masks_manifest(self, source: str) -> Path:
        """`masks/<source>/manifest.json`: what made the masks (checkpoint or class map) and for which images."""
        return self.masks_dir(source) / "manifest.json"

    # -- sites --------------------------------------------------------------------------------------------------

    def sites_index(self) -> Path:
        """`sites/index.json`."""
        return self.stage_dir("sites") / "index.json"

    def site_manifest(self, site_id: str) -> Path:
        """`sites/<site_id>/manifest.json`."""
        return self.stage_dir("sites") / site_id / "manifest.json"

    # -- pairs and features -------------------------------------------------------------------------------------

    def pairs_dir(self, site_id: str) -> Path:
        """`pairs/<site_id>/`."""
        return self.stage_dir("pairs") / site_id

    def pairs_txt(self, site_id: str) -> Path:
        """`pairs/<site_id>/pairs.txt`."""
        return self.pairs_dir(site_id) / "pairs.txt"

    def pairs_json(self, site_id: str) -> Path:
        """`pairs/<site_id>/pairs.json`."""
        return self.pairs_dir(site_id) / "pairs.json"

    def features_dir(self, site_id: str) -> Path:
        """`features/<site_id>/`."""
        return self.stage_dir("features") / site_id

    def features_db(self, site_id: str) -> Path:
        """`features/<site_id>/database.db`."""
        return self.features_dir(site_id) / "database.db"

    def features_report(self, site_id: str) -> Path:
        """`features/<site_id>/features.json`."""
        return self.features_dir(site_id) / "features.json"

    def features_extraction(self, site_id: str) -> Path:
        """`features/<site_id>/extraction.json`: what the database's features were extracted with."""
        return self.features_dir(site_id) / "extraction.json"

    # -- SfM ----------------------------------------------------------------------------------------------------

    def sfm_dir(self, site_id: str) -> Path:
        """`sfm/<site_id>/`."""
        return self.stage_dir("sfm") / site_id

    def sfm_model(self, site_id: str) -> Path:
        """`sfm/<site_id>/model/`: the merged site model."""
        return self.sfm_dir(site_id) / "model"

    def sfm_clips(self, site_id: str) -> Path:
        """`sfm/<site_id>/clips/`: one model folder per clip, named by its scene."""
        return self.sfm_dir(site_id) / "clips"

    def sfm_poses(self, site_id: str) -> Path:
        """`sfm/<site_id>/poses.json`."""
        return self.sfm_dir(site_id) / "poses.json"

    def sfm_points(self, site_id: str) -> Path:
        """`sfm/<site_id>/points.npz`."""
        return self.sfm_dir(site_id) / "points.npz"

    def sfm_report(self, site_id: str) -> Path:
        """`sfm/<site_id>/report.json`."""
        return self.sfm_dir(site_id) / "report.json"

    # -- surface and proposals ----------------------------------------------------------------------------------

    def surface_dir(self, site_id: str) -> Path:
        """`surface/<site_id>/`."""
        return self.stage_dir("surface") / site_id

    def surface_bev(self, site_id: str) -> Path:
        """`surface/<site_id>/bev/`: the site's BEV raster folder (`Workspace.locate` goes back)."""
        return self.surface_dir(site_id) / "bev"

    def surface_mesh(self, site_id: str) -> Path:
        """`surface/<site_id>/mesh.ply`."""
        return self.surface_dir(site_id) / "mesh.ply"

    def surface_kerb_step(self, site_id: str) -> Path:
        """`surface/<site_id>/kerb_step.npy`: metres above the BEV elevation, on the BEV grid."""
        return self.surface_dir(site_id) / "kerb_step.npy"

    def surface_report(self, site_id: str) -> Path:
        """`surface/<site_id>/report.json`."""
        return self.surface_dir(site_id) / "report.json"

    def proposals(self, site_id: str) -> Path:
        """`proposals/<site_id>.json`: VMA proposals in the frame of the site's rasters."""
        return self.stage_dir("proposals") / f"{site_id}.json"
