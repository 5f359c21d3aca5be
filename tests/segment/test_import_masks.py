"""`cama import-masks`: class maps from the published label lists, a Vistas-labelled mask mapped to the project's
classes, and bad masks (wrong size, unknown id, missing, several channels) refused with nothing half-imported."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.data import DatasetError, load_dataset, mask_roots
from cama_pipeline.data.schema import SEMANTIC_DIR
from cama_pipeline.segment.class_maps import (
    BUILTIN_CLASS_MAPS,
    CLASS_MAP_SCHEMA,
    ClassMapError,
    load_class_map,
)
from cama_pipeline.segment.import_masks import import_masks, mask_candidates
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from tests.data.nuscenes_fixture import NuScenesFixture, sample_data_token, write_nuscenes_fixture

VISTAS_ROAD, VISTAS_MARKING, VISTAS_CROSSWALK, VISTAS_CURB = 13, 24, 23, 2
VISTAS_CAR, VISTAS_EGO, VISTAS_SKY, VISTAS_BUILDING = 55, 64, 27, 17


@pytest.mark.parametrize(
    ("name", "ids"),
    [
        ("cityscapes", list(range(34))),
        ("cityscapes-trainids", [*range(19), 255]),
        ("mapillary-vistas", list(range(66))),
        ("mapillary-vistas-v2", list(range(124))),
        ("cama", list(range(9))),
    ],
)
def test_built_in_maps_list_every_published_id(name: str, ids: list[int]) -> None:
    class_map = load_class_map(name)
    assert sorted(class_map.targets) == ids and class_map.source == "built-in"


def test_built_in_maps_send_the_published_classes_where_the_project_wants_them() -> None:
    vistas = load_class_map("mapillary-vistas")
    named = {vistas.names[i]: vistas.targets[i] for i in vistas.targets}
    assert named["Road"] is Semantic.ROAD and named["Lane Marking - General"] is Semantic.LANE_MARKING
    assert named["Lane Marking - Crosswalk"] is Semantic.CROSSWALK
    assert named["Curb"] is Semantic.CURB and named["Curb Cut"] is Semantic.CURB
    assert named["Car"] is named["Truck"] is named["Bus"] is named["Person"] is Semantic.VEHICLE
    assert named["Ego Vehicle"] is named["Car Mount"] is Semantic.EGO
    assert named["Sky"] is Semantic.SKY and named["Building"] is named["Pole"] is Semantic.STATIC_OBJECT
    v2 = load_class_map("mapillary-vistas-v2")
    v2_named = {v2.names[i]: v2.targets[i] for i in v2.targets}
    assert v2_named["Lane Marking - Dashed Line"] is Semantic.LANE_MARKING
    assert v2_named["Lane Marking - Arrow (Left)"] is Semantic.ROAD  # paint that is no divider
    assert v2.names[120] == "Ego Vehicle" and v2.targets[120] is Semantic.EGO
    cityscapes = load_class_map("cityscapes")
    assert cityscapes.names[1] == "ego vehicle" and cityscapes.targets[1] is Semantic.EGO
    assert cityscapes.names[7] == "road" and cityscapes.targets[7] is Semantic.ROAD
    trainids = load_class_map("cityscapes-trainids")
    assert trainids.names[13] == "car" and trainids.targets[13] is Semantic.VEHICLE
    assert set(BUILTIN_CLASS_MAPS) == {
        "cityscapes",
        "cityscapes-trainids",
        "mapillary-vistas",
        "mapillary-vistas-v2",
        "cama",
    }
    cama = load_class_map("cama")
    assert all(int(target) == label for label, target in cama.targets.items())


def write_map(tmp_path: Path, classes: object, **fields: object) -> Path:
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"schema": CLASS_MAP_SCHEMA, "name": "mine", "classes": classes, **fields}))
    return path


def test_a_class_map_file_is_read_and_checked(tmp_path: Path) -> None:
    good = write_map(tmp_path, [{"id": 0, "name": "asphalt", "to": "road"}, {"id": 300, "to": "curb"}])
    class_map = load_class_map(str(good))
    assert class_map.targets == {0: Semantic.ROAD, 300: Semantic.CURB} and class_map.source == str(good)
    bad_cases = [
        ([{"id": 0, "to": "road"}, {"id": 0, "to": "curb"}], "classes[1]: id 0 listed twice"),
        ([{"id": 0, "to": "tarmac"}], "classes[0]: 'to' must be one of background, road"),
        ([{"id": 70000, "to": "road"}], "classes[0]: 'id' must be an integer 0-65535"),
        ([{"id": True, "to": "road"}], "'id' must be an integer"),
        ([], "'classes' must be a non-empty list"),
    ]
    for classes, message in bad_cases:
        path = write_map(tmp_path, classes)
        with pytest.raises(ClassMapError, match=message.replace("(", r"\(").replace("[", r"\[")) as info:
            load_class_map(path)
        assert str(path) in str(info.value)
    (tmp_path / "other.json").write_text(json.dumps({"schema": "something/1"}))
    with pytest.raises(ClassMapError, match="not a class map"):
        load_class_map(tmp_path / "other.json")
    with pytest.raises(ClassMapError, match="neither a built-in class map"):
        load_class_map("vistas")


@pytest.fixture
def bare(tmp_path: Path) -> NuScenesFixture:
    """A data set without masks: 2 samples, 1 sweep each, 6 cameras of 16 x 8 px."""
    return write_nuscenes_fixture(tmp_path / "nuscenes", with_masks=False, n_samples=2)


def vistas_mask(width: int, height: int) -> np.ndarray:
    """Sky on top, a car, road with a lane marking and a crosswalk, a curb, the ego vehicle at the bottom."""
    mask = np.full((height, width), VISTAS_ROAD, np.uint8)
    mask[0] = VISTAS_SKY
    mask[1, :4] = VISTAS_BUILDING
    mask[1, 4:8] = VISTAS_CAR
    mask[2:6, 3] = VISTAS_MARKING
    mask[2:6, 10] = VISTAS_MARKING
    mask[4, 12:15] = VISTAS_CROSSWALK
    mask[2:6, 0] = VISTAS_CURB
    mask[-1] = VISTAS_EGO
    return mask


def write_vistas_masks(
    fixture: NuScenesFixture, folder: Path, *, flat_channels: tuple[str, ...] = ()
) -> None:
    """A Vistas mask for every camera image: nested layout, flat for the cameras named."""
    for record in fixture.read_table("sample_data"):
        filename = record["filename"]
        if not filename.endswith(".jpg"):
            continue
        nested, flat = mask_candidates(folder, filename)
        path = flat if any(f"/{c}/" in filename for c in flat_channels) else nested
        path.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), vistas_mask(fixture.width, fixture.height))


def test_a_vistas_labelled_mask_is_mapped_to_the_project_classes(
    bare: NuScenesFixture, tmp_path: Path
) -> None:
    source = tmp_path / "oneformer"
    write_vistas_masks(bare, source, flat_channels=("CAM_BACK",))
    result = import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    (item,) = result.items
    ws = Workspace.for_dataset(bare.root)
    assert item.path == ws.masks_dir("imported") and not item.skipped
    assert (
        ws.masks_manifest("imported").is_file()
        and item.report["made_by"]["class_map"]["name"] == "mapillary-vistas"
    )
    dataset = load_dataset(bare.root, mask_roots=mask_roots("imported", bare.root, ws))
    for channel in ("CAM_FRONT", "CAM_BACK"):  # nested and flat layouts
        image = dataset.image(sample_data_token(channel, 1))
        semantic = image.load_semantic()
        expected = load_class_map("mapillary-vistas").table()[vistas_mask(bare.width, bare.height)]
        assert np.array_equal(semantic, expected)
        assert semantic[0, 0] == Semantic.SKY and semantic[-1, 0] == Semantic.EGO
        assert semantic[1, 5] == Semantic.VEHICLE and semantic[3, 0] == Semantic.CURB
        instances = image.load_instance()
        markings = np.unique(instances[semantic == Semantic.LANE_MARKING])
        assert len(markings) == 2 and all(m // INSTANCE_ID_BASE == Semantic.LANE_MARKING for m in markings)
        assert np.all(instances[semantic == Semantic.ROAD] == 0)
    (again,) = import_masks(bare.root, source, "mapillary-vistas", show_progress=False).items
    assert again.skipped


def state_of(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` with its bytes (symlinks followed)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_bad_masks_are_refused_naming_the_file_and_nothing_is_half_imported(
    bare: NuScenesFixture, tmp_path: Path
) -> None:
    source = tmp_path / "oneformer"
    write_vistas_masks(bare, source)
    import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    masks_root = Workspace.for_dataset(bare.root).stage_dir("masks")
    before = state_of(masks_root)
    target = next(p for p in source.rglob("*CAM_FRONT_LEFT*.png") if "samples" in p.parts)  # a needed one
    good = target.read_bytes()

    cv2.imwrite(str(target), np.full((bare.height, bare.width + 2), VISTAS_ROAD, np.uint8))
    with pytest.raises(DatasetError, match=f"mask is {bare.width + 2}x{bare.height} px") as info:
        import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    assert str(target) in str(info.value)

    unknown = vistas_mask(bare.width, bare.height)
    unknown[3, 3] = 99  # Vistas v1.2 has ids 0-65
    cv2.imwrite(str(target), unknown)
    with pytest.raises(
        ClassMapError, match="label id\\(s\\) 99 not in class map 'mapillary-vistas'"
    ) as info2:
        import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    assert str(target) in str(info2.value)

    cv2.imwrite(str(target), np.zeros((bare.height, bare.width, 3), np.uint8))
    with pytest.raises(DatasetError, match="single-channel") as info3:
        import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    assert str(target) in str(info3.value)

    target.unlink()
    with pytest.raises(FileNotFoundError, match="no mask for 1 of the") as info4:
        import_masks(bare.root, source, "mapillary-vistas", show_progress=False)
    image_name = target.stem
    assert image_name in str(info4.value)

    assert state_of(masks_root) == before  # the first import stands, no staging folder left
    target.write_bytes(good)  # mended (a new file time): imported again, to the same masks
    (mended,) = import_masks(bare.root, source, "mapillary-vistas", show_progress=False).items
    assert not mended.skipped
    after = state_of(masks_root)
    assert {k: v for k, v in after.items() if not k.endswith("manifest.json")} == {
        k: v for k, v in before.items() if not k.endswith("manifest.json")
    }


def test_a_first_import_that_fails_leaves_no_masks(bare: NuScenesFixture, tmp_path: Path) -> None:
    source = tmp_path / "cityscapes"
    write_vistas_masks(bare, source)  # Vistas' 55 (car) and 64 (ego) are no Cityscapes labelIds
    with pytest.raises(ClassMapError, match="not in class map 'cityscapes'"):
        import_masks(bare.root, source, "cityscapes", show_progress=False)
    masks = Workspace.for_dataset(bare.root).stage_dir("masks")
    assert not masks.exists() or not any(masks.iterdir())


def test_cli_imports_and_exits_2_on_bad_masks(bare: NuScenesFixture, tmp_path: Path) -> None:
    runner = CliRunner()
    source = tmp_path / "oneformer"
    write_vistas_masks(bare, source)
    workspace = tmp_path / "ws"
    argv = ["import-masks", str(bare.root), str(source), "--class-map", "mapillary-vistas"]
    done = runner.invoke(app, [*argv, "--workspace", str(workspace)])
    assert done.exit_code == 0, done.output
    assert "imported" in done.output and (Workspace(workspace).masks_dir("imported") / SEMANTIC_DIR).is_dir()
    wrong = runner.invoke(app, [*argv[:-1], "cityscapes", "--workspace", str(workspace)])
    assert wrong.exit_code == 2 and "not in class map 'cityscapes'" in wrong.output
    missing = runner.invoke(app, [*argv[:2], str(tmp_path / "none"), *argv[3:]])
    assert missing.exit_code == 2 and "mask folder not found" in missing.output


def test_import_processes_write_what_one_process_writes(bare: NuScenesFixture, tmp_path: Path) -> None:
    source = tmp_path / "oneformer"
    write_vistas_masks(bare, source)
    written = {}
    for workers in (1, 2):
        workspace = Workspace(tmp_path / f"ws-{workers}")
        import_masks(bare.root, source, "mapillary-vistas", workspace, workers=workers, show_progress=False)
        files = state_of(workspace.masks_dir("imported"))
        written[workers] = {k: v for k, v in files.items() if not k.endswith("manifest.json")}
    assert len(written[1]) == 2 * 24 and written[1] == written[2]  # 24 images, semantic and lane instances
