"""What names a generated site, and the check that a model is never measured on (or validated on) a site it saw.

A site (`SiteIdentity`) is named by the generator's manifest (`cama synth`, and the VMA's BEV-only sites): its
preset, seed, location, the digest of its layout config and of its whole config. Two sites are one place when
they share a preset and seed, a layout or a location (a location is its own map frame; presets draw their
layouts differently, so one seed in two presets is two places). Models record the identities of the
sites they trained on (the segmenter's and the VMA's checkpoints), and `ensure_not_among` refuses a site that is
one place with any of them.
"""

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any


class SeenSiteError(ValueError):
    """A model asked to be scored on (or trained on) a site it must not see; names the site."""


@dataclass(frozen=True)
class SiteIdentity:
    """What names a generated site: from its `manifest.json` (written by `cama synth`)."""

    path: str
    preset: str
    seed: int
    location: str
    layout_digest: str
    config_digest: str

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "SiteIdentity":
        return cls(**{k: data[k] for k in cls.__dataclass_fields__})

    def shares_with(self, other: "SiteIdentity") -> str | None:
        """What this site has in common with `other` that makes them one place (the seed of one preset, the
        layout, the location)."""
        if self.seed == other.seed and self.preset == other.preset:
            return f"seed {self.seed}"
        if self.layout_digest == other.layout_digest:
            return f"layout {self.layout_digest}"
        if self.location == other.location:
            return f"location {self.location!r}"
        return None


def _digest(value: Any) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


def site_identity(site: Path) -> SiteIdentity:
    """The identity of a generated site folder (`<site>/manifest.json`); FileNotFoundError / ValueError naming
    the file when the folder is not a generated site."""
    manifest = Path(site) / "manifest.json"
    if not manifest.is_file():
        raise FileNotFoundError(f"{manifest}: not found; not a site written by `cama synth`")
    try:
        data = json.loads(manifest.read_text(encoding="utf-8"))
        return identity_from_manifest(data, Path(site))
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{manifest}: not a generator manifest ({type(err).__name__}: {err})") from None


def identity_from_manifest(data: dict[str, Any], site: Path) -> SiteIdentity:
    """The identity a generator manifest's content gives the site in folder `site` (KeyError, TypeError or
    ValueError when a field is missing or mistyped)."""
    config = data["config"]
    preset, seed = str(data["preset"]), int(data["seed"])
    location = config.get("location") or f"synthetic-{preset}"
    return SiteIdentity(
        str(Path(site).absolute()), preset, seed, str(location), _digest(config["layout"]), _digest(config)
    )


def ensure_not_among(identity: SiteIdentity, seen: Iterable[SiteIdentity], model: str) -> SiteIdentity:
    """`identity` when it is one place with none of `seen`; SeenSiteError naming the site, the `model` and the
    seen site it shares a seed, layout or location with (scores on a seen site would flatter the model)."""
    for other in seen:
        shared = identity.shares_with(other)
        if shared is not None:
            raise SeenSiteError(
                f"{identity.path}: {model} was trained on {other.path}, which has the same {shared}; "
                "measure it on a site it never saw"
            )
    return identity
