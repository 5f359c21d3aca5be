"""The configuration of a whole run (`cama run`): run-level choices and every stage's own config, read from TOML
or YAML and written as TOML.

A file sets any stage parameter; what it leaves out keeps its default, so a file need hold only what differs:

```toml
workers = 4                      # run-level choices: executor, workers, proposer, checkpoint, surface_poses,
                                 # masks, scenes

[features]
max_num_features = 2048          # a table per stage, named as in `cama run --stop-after`: [wigo] [keyframes]
                                 # [sites] [pairs] [segment] [features] [sfm] [sfm_merge] [surface] [propose]
[propose.rule]
join_gap_m = 6.0                 # nested settings are nested tables
```

Every key is checked against the config it names: an unknown key, a value of the wrong type, or a value the
stage's config refuses is a `ConfigError` naming the file and the dotted key (`cama run` exits 2). TOML has no
null: a field that may be unset (`checkpoint`, `sfm.first_ba_max_iterations`) is unset by the empty string.
Integers are accepted for float fields (and stored as floats, so `10` and `10.0` give the same fingerprint).

`dump_toml` writes every field of the effective configuration (`cama run --print-config`); `load_config` reads
it back to an equal config. Each stage runs with its table; its fingerprint holds that config, so changing a
parameter reruns that stage and, through their inputs, the stages after it.
"""

import dataclasses
import difflib
import json
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from cama_pipeline.data.masks import parse_mask_choice
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.segment.config import SegmentConfig
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.merge import MergeConfig
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.wigo.config import WigoConfig
from models.vma.infer import InferenceConfig
from models.vma.propose import boundary_source_for
from models.vma.rule_based import RuleConfig

BoundarySource = Literal["auto", "curb", "road_edge"]


class ConfigError(ValueError):
    """A configuration file that cannot be read or holds a bad key or value; the message names file and key."""


@dataclass(frozen=True)
class ProposeConfig:
    """The VMA proposal stage: the settings of `models.vma.propose.propose` for every site."""

    min_confidence: float = 0.1
    """Proposals scoring lower are dropped."""
    boundary_source: BoundarySource = "auto"
    """auto: road_edge on a surface stage's rasters (what `cama run` proposes on), curb on a generator's; the
    rule settings below then take it (`models.vma.propose.boundary_source_for`)."""
    rule: RuleConfig = field(default_factory=RuleConfig)
    """The rule-based proposer, and an anchored model's candidates (its `boundary_source` is the one above)."""
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    """The learned proposer's sliding windows (its `rule` is the table above)."""

    def __post_init__(self) -> None:
        if self.boundary_source not in ("auto", "curb", "road_edge"):
            raise ValueError(
                f"ProposeConfig.boundary_source must be auto, curb or road_edge, got {self.boundary_source!r}"
            )
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError(f"ProposeConfig.min_confidence must be in [0, 1], got {self.min_confidence}")

    def rule_for(self, rasters: Path) -> RuleConfig | None:
        """The rule settings for one site's raster folder, `auto` resolved there (`boundary_source_for`). None
        when the boundary source is auto and the rule table untouched: `propose` then resolves it itself,
        exactly as `cama propose` does."""
        if self.boundary_source != "auto":
            return dataclasses.replace(self.rule, boundary_source=self.boundary_source)
        if self.rule == RuleConfig():
            return None
        return dataclasses.replace(self.rule, boundary_source=boundary_source_for(rasters))


@dataclass(frozen=True)
class PipelineConfig:
    """The whole path: the run-level choices, then one config per stage (each stage's defaults unless set)."""

    executor: Literal["local", "ray"] = "local"
    """Where SfM clips run."""
    workers: int = 2
    """SfM processes (or Ray tasks) at once."""
    proposer: Literal["learned", "rule", "masks"] = "masks"
    """The element-mask network (its geometry is what retraining on corrections changes), the learned
    MapTR-style model (rule-based candidates, rescored and refined), or the rule-based proposer."""
    checkpoint: Path | None = None
    """Checkpoint registry or version folder for the learned or element-mask proposer (of that kind); None: the
    one shipped with the package (`models.vma.shipped`), found from any working directory."""
    surface_poses: Literal["sfm", "wigo"] = "sfm"
    """Poses the surface stage projects the images with."""
    masks: str = "auto"
    """Where the image masks come from (`cama_pipeline.data.masks`): auto (the data set's own, else the workspace's
    predicted, else its imported; the segment stage runs when none is there), dataset, predicted (the segment
    stage makes them), imported (`cama import-masks`) or a folder laid out like a data set's masks."""
    scenes: tuple[str, ...] = ()
    """The scenes (names) the run works on; empty: every scene of the data set. On a large data set (nuScenes
    v1.0-trainval's 850 scenes) the stages then read only these scenes' records (`load_dataset(scenes=...)`)."""
    wigo: WigoConfig = field(default_factory=WigoConfig)
    keyframes: KeyframeConfig = field(default_factory=KeyframeConfig)
    sites: SiteConfig = field(default_factory=SiteConfig)
    pairs: PairsConfig = field(default_factory=PairsConfig)
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    """The segmenter, when the run needs predicted masks (`masks`)."""
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    sfm: SfmConfig = field(default_factory=SfmConfig)
    sfm_merge: MergeConfig = field(default_factory=MergeConfig)
    """How the SfM stage merges a site's clips."""
    surface: SurfaceConfig = field(default_factory=SurfaceConfig)
    propose: ProposeConfig = field(default_factory=ProposeConfig)

    def __post_init__(self) -> None:
        if self.executor not in ("local", "ray"):
            raise ValueError(f"executor must be local or ray, got {self.executor!r}")
        if self.proposer not in ("learned", "rule", "masks"):
            raise ValueError(f"proposer must be learned, rule or masks, got {self.proposer!r}")
        if self.surface_poses not in ("sfm", "wigo"):
            raise ValueError(f"surface_poses must be sfm or wigo, got {self.surface_poses!r}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {self.workers!r}")
        if not isinstance(self.masks, str) or not self.masks.strip():
            raise ValueError(
                f"masks must be auto, dataset, predicted, imported or a folder, got {self.masks!r}"
            )
        parse_mask_choice(self.masks)
        if any(not isinstance(name, str) or not name.strip() for name in self.scenes):
            raise ValueError(f"scenes must be scene names, got {list(self.scenes)!r}")
        if len(set(self.scenes)) != len(self.scenes):
            raise ValueError(f"scenes names a scene twice: {list(self.scenes)!r}")


HIDDEN_FIELDS: dict[type, frozenset[str]] = {
    RuleConfig: frozenset({"boundary_source"}),  # ProposeConfig.boundary_source ("auto" resolves per site)
    InferenceConfig: frozenset({"rule"}),  # ProposeConfig.rule
}
"""Fields a file neither shows nor sets: another field of the configuration decides them."""


def load_config(path: Path) -> PipelineConfig:
    """The configuration in a TOML (`.toml`) or YAML (`.yaml`, `.yml`) file; ConfigError naming file and key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the configuration: {err.strerror or err}") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        table = _parse_yaml(text, path)
    else:
        try:
            table = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"{path}: not valid TOML: {err}") from None
    return from_table(PipelineConfig, table, source=str(path))


def _parse_yaml(text: str, path: Path) -> object:
    import yaml  # PyYAML: only for YAML files

    try:
        parsed = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from None
    return {} if parsed is None else parsed


def from_table(cls: type[Any], table: object, *, source: str, key: str = "") -> Any:
    """An instance of the dataclass `cls` from a parsed table: its defaults overridden by the table's keys."""
    where = f"[{key}]" if key else "the top level"
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: {key or 'the file'} must be a table of keys, got {table!r}")
    hints = typing.get_type_hints(cls)
    known = [f.name for f in dataclasses.fields(cls) if f.name not in HIDDEN_FIELDS.get(cls, ())]
    values: dict[str, Any] = {}
    for name, value in table.items():
        dotted = f"{key}.{name}" if key else str(name)
        if name not in known:
            close = difflib.get_close_matches(str(name), known, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(known)}"
            raise ConfigError(f"{source}: unknown key {dotted!r} in {where}{hint}")
        values[name] = _value(hints[name], value, source=source, key=dotted)
    try:
        return cls(**values)
    except ValueError as err:
        raise ConfigError(f"{source}: {where}: {err}") from None


def _value(kind: Any, value: object, *, source: str, key: str) -> Any:
    """`value` checked against the annotation `kind` and converted (lists to tuples, str to Path, ...)."""
    origin, args = get_origin(kind), get_args(kind)
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        return from_table(kind, value, source=source, key=key)
    if origin in (types.UnionType, typing.Union):
        inner = [a for a in args if a is not type(None)]
        if (value is None or value == "") and len(inner) < len(args):
            return None  # TOML's "" or YAML's null
        return _value(inner[0], value, source=source, key=key)

    def refuse(expected: str) -> ConfigError:
        return ConfigError(f"{source}: {key} must be {expected}, got {value!r}")

    if origin is Literal:
        if value not in args:
            raise refuse("one of " + ", ".join(repr(a) for a in args))
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise refuse("a list")
        fixed = not (len(args) == 2 and args[1] is Ellipsis)
        if fixed and len(value) != len(args):
            raise refuse(f"a list of {len(args)} values")
        items = args if fixed else [args[0]] * len(value)
        return tuple(
            _value(k, v, source=source, key=f"{key}[{i}]")
            for i, (k, v) in enumerate(zip(items, value, strict=True))
        )
    if kind is bool:
        if not isinstance(value, bool):
            raise refuse("true or false")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise refuse("an integer")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise refuse("a number")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise refuse("a string")
        return value
    if kind is Path:
        if not isinstance(value, str) or not value:
            raise refuse("a path")
        return Path(value)
    raise TypeError(f"{key}: no file form for a field of type {kind!r}")  # a new field type: add it here


def to_table(config: object) -> dict[str, Any]:
    """Every shown field of a config dataclass as TOML-ready values (None as "", paths as strings)."""
    hidden = HIDDEN_FIELDS.get(type(config), frozenset())
    table: dict[str, Any] = {}
    for f in dataclasses.fields(config):  # type: ignore[arg-type]
        if f.name not in hidden:
            table[f.name] = _plain(getattr(config, f.name))
    return table


def _plain(value: object) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_table(value)
    if value is None:
        return ""
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def dump_toml(config: PipelineConfig) -> str:
    """The whole configuration as TOML, every field written: `load_config` reads it back to an equal config."""
    lines = [
        "# cama run configuration: every field, the defaults unless set. Save it, edit it, and pass it back",
        '# with `cama run DATASET --config FILE`; a file need only hold what differs. "" leaves a field unset.',
        "",
    ]
    _write_table(lines, "", to_table(config))
    return "\n".join(lines).rstrip("\n") + "\n"


def _write_table(lines: list[str], name: str, table: dict[str, Any]) -> None:
    if name:
        lines.append(f"[{name}]")
    lines += [f"{key} = {_toml_value(value)}" for key, value in table.items() if not isinstance(value, dict)]
    lines.append("")
    for key, value in table.items():
        if isinstance(value, dict):
            _write_table(lines, f"{name}.{key}" if name else key, value)


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")
