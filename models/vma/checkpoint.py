"""Versioned VMA checkpoints: weights with their model config, metrics and the data they saw.

A registry folder holds one sub-folder per version (`v0001`, `v0002`, ...), each with `model.pt` (float16
state dict) and `checkpoint.json` (version, parent, model config and its fingerprint, train config, metrics,
data), plus `current.json` naming the promoted version that proposers load. `data.seen_sites` lists the
identity (`cama_pipeline.site_identity`) of every generated site the version and its parents trained on, and
`data.seen_folders` every folder they trained on (corrections' sites have no generator identity);
`ensure_unseen` refuses to let a version be scored on any of them. Versions are written atomically
(staged, then renamed) and never changed afterwards, except that a rejected candidate stays unpromoted.
"""

import json
import logging
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol, TypeVar

import torch

from cama_pipeline.io import atomic_write_json
from cama_pipeline.site_identity import SeenSiteError, SiteIdentity, ensure_not_among, site_identity
from models.vma.config import ModelConfig, config_dict, config_fingerprint
from models.vma.model import VmaNet
from models.vma.validation import ValidationEntry, truth_folder

logger = logging.getLogger(__name__)

CURRENT = "current.json"
WEIGHTS = "model.pt"
META = "checkpoint.json"

MAPTR_KIND = "maptr"
"""`kind` of the MapTR-style model's versions (their `checkpoint.json` has no `kind` field)."""

ModuleT = TypeVar("ModuleT", bound=torch.nn.Module)


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (missing, unreadable, or made for another model config)."""


class VersionRecord(Protocol):
    """What the seen-site checks read of a loaded version, whichever network it holds."""

    @property
    def meta(self) -> dict[str, Any]: ...

    @property
    def path(self) -> Path: ...


@dataclass(frozen=True)
class Checkpoint:
    """A loaded checkpoint: the model (eval mode) and its metadata."""

    model: VmaNet
    config: ModelConfig
    meta: dict[str, Any]
    path: Path


def stored_state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """The model's state as a version folder stores it: floating-point tensors in float16 (half the size)."""
    return {k: v.half() if v.is_floating_point() else v for k, v in model.state_dict().items()}


def round_to_stored(model: ModuleT) -> ModuleT:
    """`model` with its weights rounded in place to the precision a version folder stores them in: a retrained
    candidate is gated as the network that will be saved and loaded, not as its float32 self (the two propose
    differently enough to move the simulated annotator's time by seconds)."""
    model.load_state_dict(stored_state(model))  # copied into the float32 tensors, so rounded and cast back
    return model


def save_version(registry: Path, model: torch.nn.Module, meta: dict[str, Any]) -> Path:
    """Write the model (a VMA network with its frozen `config`) as the next version of `registry`; returns its
    folder (not promoted yet)."""
    registry = Path(registry)
    registry.mkdir(parents=True, exist_ok=True)
    existing = sorted(p.name for p in registry.glob("v[0-9][0-9][0-9][0-9]") if p.is_dir())
    version = f"v{int(existing[-1][1:]) + 1 if existing else 1:04d}"
    staging = registry / f".{version}.partial"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    torch.save(stored_state(model), staging / WEIGHTS)
    full_meta = {
        **meta,
        "version": version,
        "model_config": config_dict(model.config),
        "config_fingerprint": config_fingerprint(model.config),
        "created_at": datetime.now(UTC).isoformat(),
    }
    atomic_write_json(staging / META, full_meta, indent=2)
    staging.rename(registry / version)
    logger.info("saved checkpoint %s", registry / version)
    return registry / version


def checkpoint_kind(path: Path) -> str:
    """Which network a registry's promoted version (or a version folder) holds: its `kind` field,
    'maptr' for versions without one (the MapTR-style model's, saved before kinds existed)."""
    meta_path = current_version(Path(path)) / META
    try:
        return str(json.loads(meta_path.read_text(encoding="utf-8")).get("kind", MAPTR_KIND))
    except (OSError, json.JSONDecodeError, AttributeError) as err:
        raise CheckpointError(f"{meta_path}: unreadable checkpoint metadata: {err!r}") from None


def promote(registry: Path, version: str) -> None:
    """Make `version` the one proposers load."""
    if not (Path(registry) / version / META).is_file():
        raise CheckpointError(f"{registry}: no checkpoint version {version!r} to promote")
    atomic_write_json(Path(registry) / CURRENT, {"version": version}, indent=2)
    logger.info("promoted %s/%s", registry, version)


def current_version(registry: Path) -> Path:
    """The promoted version folder of a registry (or `registry` itself when it is a version folder)."""
    registry = Path(registry)
    if (registry / META).is_file():
        return registry
    pointer = registry / CURRENT
    if not pointer.is_file():
        raise CheckpointError(f"{registry}: neither a checkpoint ({META}) nor a registry with {CURRENT}")
    try:
        version = json.loads(pointer.read_text(encoding="utf-8"))["version"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise CheckpointError(f"{pointer}: needs {{'version': 'vNNNN'}}: {err!r}") from None
    return registry / str(version)


def load_checkpoint(path: Path, expected: ModelConfig | None = None, device: str = "cpu") -> Checkpoint:
    """Load a checkpoint folder (or a registry's promoted one); CheckpointError on another model config."""
    folder = current_version(path)
    meta_path = folder / META
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        config = ModelConfig(**meta["model_config"])
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{meta_path}: unreadable checkpoint metadata: {err!r}") from None
    if meta.get("config_fingerprint") != config_fingerprint(config):
        raise CheckpointError(f"{meta_path}: config_fingerprint does not match its model_config")
    if expected is not None and config_fingerprint(expected) != config_fingerprint(config):
        raise CheckpointError(
            f"{meta_path}: checkpoint was trained for another model config "
            f"({config_fingerprint(config)} != expected {config_fingerprint(expected)})"
        )
    model = load_weights(VmaNet(config), folder, device)
    return Checkpoint(model, config, meta, folder)


def load_weights(model: ModuleT, folder: Path, device: str) -> ModuleT:
    """`model` with the (float16-saved) weights of a version folder, on `device` in eval mode; CheckpointError
    naming the file when they do not fit."""
    try:
        state = torch.load(folder / WEIGHTS, map_location=device, weights_only=True)
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
    except (OSError, RuntimeError) as err:
        raise CheckpointError(f"{folder / WEIGHTS}: weights do not fit the model config: {err}") from None
    model.to(device).eval()
    return model


def seen_sites(checkpoint: VersionRecord) -> tuple[SiteIdentity, ...]:
    """The generated sites a version (and its parents) trained on; CheckpointError for a version that does not
    record them (it could not be kept off its own training sites)."""
    data = checkpoint.meta.get("data", {})
    if "seen_sites" not in data:
        raise CheckpointError(
            f"{checkpoint.path / META}: field 'data.seen_sites' missing: the sites it trained on are unknown"
        )
    try:
        return tuple(SiteIdentity.from_json(entry) for entry in data["seen_sites"])
    except (KeyError, TypeError) as err:
        raise CheckpointError(f"{checkpoint.path / META}: field 'data.seen_sites': {err!r}") from None


def ensure_unseen(checkpoint: VersionRecord, site: Path) -> SiteIdentity | None:
    """Refuse (SeenSiteError) to let a version be scored on a site it trained on (`refuse_seen`)."""
    folders = checkpoint.meta.get("data", {}).get("seen_folders", [])
    return refuse_seen(site, seen_sites(checkpoint), folders, f"VMA checkpoint {checkpoint.path}")


def refuse_seen(
    site: Path, seen: Sequence[SiteIdentity], folders: Sequence[str], model: str
) -> SiteIdentity | None:
    """SeenSiteError naming `site` and `model` when `site` is one of the `folders` trained on or holds one or lies
    in one (a site folder and its raster folder are one site), or is a generated site (one with a generator
    manifest) sharing a seed, layout or location with a `seen` site. Returns the site's identity (None for a
    folder without a generator manifest)."""
    here = Path(site).absolute()
    for folder in (Path(f).absolute() for f in folders):
        if here == folder or here in folder.parents or folder in here.parents:
            raise SeenSiteError(
                f"{site}: {model} was trained on this folder ({folder}); measure it on a site it never saw"
            )
    if not (Path(site) / "manifest.json").is_file():
        return None
    return ensure_not_among(site_identity(site), seen, model)


def refuse_seen_validation(
    records: dict[str, list[Any]], validation_sites: Sequence[ValidationEntry], model: str
) -> None:
    """`refuse_seen` for each validation site against a new version's `seen_records`."""
    identities = [SiteIdentity.from_json(entry) for entry in records["seen_sites"]]
    for site in validation_sites:
        refuse_seen(truth_folder(site), identities, records["seen_folders"], model)


def seen_records(sites: Sequence[Path], parent: VersionRecord | None) -> dict[str, list[Any]]:
    """`data.seen_sites` and `data.seen_folders` of a new version trained on `sites` (from `parent`, if any):
    the parent's, plus the identities of those of `sites` that are generated sites and all their folders."""
    seen = [s.to_json() for s in seen_sites(parent)] if parent is not None else []
    folders = list(parent.meta["data"].get("seen_folders", [])) if parent is not None else []
    for site in sites:
        folder = str(Path(site).absolute())
        if folder not in folders:
            folders.append(folder)
        if (Path(site) / "manifest.json").is_file():
            identity = site_identity(Path(site)).to_json()
            if identity not in seen:
                seen.append(identity)
    return {"seen_sites": seen, "seen_folders": folders}
