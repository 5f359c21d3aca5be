"""The sites a proposer is scored on: true vectors from one folder, rasters (the site's own or a reconstruction's)
from another.

The product proposes on the surface stage's reconstructed rasters, with smeared curbs, holes and label noise; a
generator site's own rasters are clean. A gate that scores retrained models on clean rasters only promotes models
that are worse on reconstructions (README, "Rehearsal while retraining"), so a validation site may name the
reconstruction of a synthetic site (`cama synth` then `cama run`): the rasters are the surface stage's, the truth
is the generator's, carried into the reconstruction's frame (`cama_pipeline.evaluate.frame`: the rasters sit where
their poses' gauge put them, decimetres from the world on a small site, which no proposer or annotator can see or
mend) and cut to the cells the cameras observed (nobody can propose or draw what no image shows).
"""

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from cama_pipeline.evaluate.frame import FrameError, ReconstructionFrame, reconstruction_frame
from cama_pipeline.evaluate.observed import ObservedMask, observed_parts
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.surface.outputs import is_surface_bev
from cama_pipeline.workspace import Workspace
from models.vma.rasters import SiteInputError, SiteRasters, raster_dir_of, vector_map_of
from models.vma.vectors import Vector, read_vectors


@dataclass(frozen=True)
class ValidationSite:
    """A validation site: `site` holds the true vectors (`vector_map_of`), `rasters` the rasters proposed on (a
    raster folder, or a site whose `raster_dir_of` is one, read by `load_site_rasters`); `reconstructed` rasters
    are scored against the observed parts of the truth."""

    site: Path
    rasters: Path
    reconstructed: bool = False
    frame: ReconstructionFrame | None = None
    """Where a reconstruction's rasters sit against the world (`reconstruction_of`); None: the world's own."""

    def __str__(self) -> str:
        return f"{self.site} (reconstructed: {self.rasters})" if self.reconstructed else str(self.site)


def own_rasters(site: Path) -> ValidationSite:
    """A site scored on its own rasters (a BEV site, or a synthetic site's `ground_truth/bev/`); FileNotFoundError
    naming the site when it has none."""
    raster_dir_of(Path(site))
    return ValidationSite(Path(site), Path(site))


def reconstruction_of(site: Path, workspace: Path | None = None) -> ValidationSite:
    """A synthetic site scored on the surface stage's rasters of its data set `<site>/nuscenes` (`cama run` done
    into `workspace`, default the data set's own, with exactly one reconstructed site); SiteInputError naming
    the site and what is missing otherwise."""
    site = Path(site)
    if not (site / "ground_truth" / "vector_map.json").is_file():
        raise SiteInputError(
            f"{site}: no ground_truth/vector_map.json (not a synthetic site from `cama synth`)"
        )
    where = Workspace.resolve(workspace, site / "nuscenes")
    index = where.sites_index()
    site_ids = read_site_ids(index) if index.is_file() else []
    found = [s for s in site_ids if is_surface_bev(where.surface_bev(s))]
    if len(found) != 1:
        raise SiteInputError(
            f"{site}: expected the finished surface rasters of exactly one reconstructed site under {where.root} "
            f"(run `cama run {site / 'nuscenes'}` first), found {len(found)}"
        )
    try:
        frame = reconstruction_frame(site / "nuscenes", where, found[0])
    except (FrameError, FileNotFoundError) as error:
        raise SiteInputError(f"{site}: the reconstruction's frame: {error}") from None
    return ValidationSite(site, where.surface_bev(found[0]), reconstructed=True, frame=frame)


ValidationEntry = Path | ValidationSite
"""A validation site as the gates take it: a path is scored on its own rasters."""


def reconstructions(entries: Sequence[ValidationEntry]) -> list[ValidationSite]:
    """The entries whose rasters are a reconstruction (a path is its own rasters)."""
    return [entry for entry in entries if isinstance(entry, ValidationSite) and entry.reconstructed]


def as_validation_site(entry: ValidationEntry) -> ValidationSite:
    """A validation site as given: a path is scored on its own rasters."""
    return entry if isinstance(entry, ValidationSite) else own_rasters(Path(entry))


def truth_folder(entry: ValidationEntry) -> Path:
    """The folder whose truth a validation entry is scored against: what a checkpoint must not have seen."""
    return entry.site if isinstance(entry, ValidationSite) else Path(entry)


def true_vectors(validation: ValidationSite, rasters: SiteRasters) -> list[Vector]:
    """The truth a proposer on `rasters` (`validation.rasters`, loaded) is scored against: the site's vectors, on a
    reconstruction carried into its frame and cut to their observed parts (`observed_truth`)."""
    if not validation.reconstructed:
        return read_vectors(vector_map_of(validation.site))
    return observed_truth(validation.site, rasters, validation.frame)


def observed_truth(site: Path, rasters: SiteRasters, frame: ReconstructionFrame | None) -> list[Vector]:
    """A synthetic site's true vectors carried into a reconstruction's `frame` (None: left in the world's) and cut
    to the cells `rasters` (the reconstruction's, loaded) observed: what a proposer on those rasters can find and
    an annotator on them can draw."""
    truth = read_vectors(vector_map_of(site))
    if frame is not None:
        truth = [Vector(t.cls, frame.apply(t.points), t.score) for t in truth]
    mask = ObservedMask.from_semantic(rasters.semantic, rasters.origin_xy, rasters.resolution_m)
    return [Vector(t.cls, part) for t in truth for part in observed_parts(t.points, t.closed, mask)]
