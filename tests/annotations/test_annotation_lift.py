"""The 2D -> 3D lift: exact on a plane, holes filled from an observed cell within the radius, the rest flagged."""

import logging

import numpy as np
import pytest

from annotations import Georeference, LiftError, MapElement, lift_element, lift_points
from cama_pipeline.semantics import Semantic
from tests.annotations.annotation_helpers import RESOLUTION_M, element_kwargs, plane_z

LINE = [[1.3, 2.7], [15.2, 17.9], [8.1, 5.05]]


def _cell_centre(row: int, col: int) -> tuple[float, float]:
    """Site x, y of a test-raster cell centre."""
    return col * RESOLUTION_M, 20.0 - row * RESOLUTION_M


def test_lift_is_exact_on_a_plane(georef: Georeference, plane_elevation: np.ndarray) -> None:
    result = lift_points(LINE, plane_elevation, georef)
    assert result.ok and result.flagged == () and result.filled == ()
    points = result.points_3d
    np.testing.assert_allclose(points[:, 2], plane_z(points[:, 0], points[:, 1]), atol=1e-12)
    assert np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1).max() <= 0.5 + 1e-12
    for vertex in LINE:
        assert np.any(np.all(np.isclose(points[:, :2], vertex), axis=1))
    assert "0 flagged" in result.report
    coarse = lift_points(LINE, plane_elevation, georef, max_spacing_m=2.0)
    assert len(coarse.points_3d) < len(points)


def test_unobserved_cell_takes_the_nearest_observed_cell_within_the_radius(
    georef: Georeference, plane_elevation: np.ndarray
) -> None:
    elevation = plane_elevation.copy()
    elevation[10, 10] = np.nan  # a one-cell hole: neighbours 0.5 m away
    x, y = _cell_centre(10, 10)
    result = lift_points([[x, y], [x + 2.0, y]], elevation, georef)
    assert result.ok and result.filled == (0,)
    neighbours = [plane_z(*_cell_centre(10 + dr, 10 + dc)) for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1))]
    assert any(np.isclose(result.points_3d[0, 2], z) for z in neighbours)
    np.testing.assert_allclose(
        result.points_3d[1:, 2], plane_z(result.points_3d[1:, 0], result.points_3d[1:, 1])
    )
    assert "1 using the nearest observed cell within 1.0 m" in result.report


def test_vertex_beyond_the_radius_is_flagged_and_reported(
    georef: Georeference, plane_elevation: np.ndarray
) -> None:
    semantic = np.full(plane_elevation.shape, int(Semantic.ROAD), dtype=np.uint8)
    semantic[17:24, 17:24] = Semantic.UNOBSERVED  # 3.5 m square: its centre cell is 2 m from observed cells
    x, y = _cell_centre(20, 20)
    result = lift_points([[x - 4.0, y], [x, y]], plane_elevation, georef, unobserved=semantic)
    assert not result.ok
    flagged = np.array(result.flagged)
    assert len(result.points_3d) - 1 in result.flagged  # the vertex at the centre
    assert np.isnan(result.points_3d[flagged, 2]).all()
    lifted = np.setdiff1d(np.arange(len(result.points_3d)), flagged)
    assert np.isfinite(result.points_3d[lifted, 2]).all()
    assert f"at site ({x:.2f}, {y:.2f})" in result.report and "flagged" in result.report
    wider = lift_points(
        [[x - 4.0, y], [x, y]], plane_elevation, georef, unobserved=semantic, search_radius_m=2.0
    )
    assert wider.ok
    same = lift_points(
        [[x - 4.0, y], [x, y]], plane_elevation, georef, unobserved=semantic == Semantic.UNOBSERVED
    )
    assert same.flagged == result.flagged


def test_vertex_outside_the_raster_is_flagged(georef: Georeference, plane_elevation: np.ndarray) -> None:
    result = lift_points([[10.0, 10.0], [10.0, 30.0]], plane_elevation, georef, max_spacing_m=5.0)
    assert result.flagged == (3, 4)  # y = 20 is the top row's centre (observed); y = 25, 30 lie above it
    assert np.isfinite(result.points_3d[:2, 2]).all()


def test_lift_element_sets_points_3d(georef: Georeference, plane_elevation: np.ndarray) -> None:
    element = MapElement.model_validate(element_kwargs(points_2d=LINE, version=3))
    lifted = lift_element(element, plane_elevation, georef)
    assert lifted.version == 3 and lifted.points_2d == element.points_2d
    xyz = lifted.xyz()
    assert xyz is not None and len(xyz) > len(LINE)
    np.testing.assert_allclose(xyz[:, 2], plane_z(xyz[:, 0], xyz[:, 1]), atol=1e-12)


def test_lift_closed_crosswalk_stays_closed(georef: Georeference, plane_elevation: np.ndarray) -> None:
    ring = [[5.0, 5.0], [9.0, 5.0], [9.0, 7.0], [5.0, 7.0], [5.0, 5.0]]
    element = MapElement.model_validate(element_kwargs(**{"class": "ped_crossing", "points_2d": ring}))
    xyz = lift_element(element, plane_elevation, georef).xyz()
    assert xyz is not None
    np.testing.assert_array_equal(xyz[0], xyz[-1])


def test_lift_element_strict_raises_and_lenient_clears(
    georef: Georeference, plane_elevation: np.ndarray, caplog: pytest.LogCaptureFixture
) -> None:
    elevation = plane_elevation.copy()
    elevation[:, 30:] = np.nan  # x >= 15 m unobserved; x = 18 m is 3 m from the nearest observed cell
    element = MapElement.model_validate(element_kwargs(id="div-7", points_2d=[[10.0, 10.0], [18.0, 10.0]]))
    with pytest.raises(LiftError, match="element 'div-7': cannot lift") as info:
        lift_element(element, elevation, georef)
    assert info.value.element_id == "div-7" and info.value.flagged
    assert "at site (18.00, 10.00)" in str(info.value)
    with caplog.at_level(logging.WARNING, logger="annotations.lift"):
        lenient = lift_element(
            element.with_changes(points_3d=[(0, 0, 0), (1, 0, 0)]), elevation, georef, strict=False
        )
    assert lenient.points_3d is None
    assert "div-7" in caplog.text


def test_lift_rejects_bad_inputs(georef: Georeference, plane_elevation: np.ndarray) -> None:
    with pytest.raises(ValueError, match="elevation: raster shape"):
        lift_points(LINE, plane_elevation[:-1], georef)
    with pytest.raises(ValueError, match="unobserved: mask shape"):
        lift_points(LINE, plane_elevation, georef, unobserved=np.zeros((3, 3), dtype=bool))
    with pytest.raises(ValueError, match="unobserved: expected a boolean"):
        lift_points(LINE, plane_elevation, georef, unobserved=np.zeros(plane_elevation.shape))
    with pytest.raises(ValueError, match="max_spacing_m"):
        lift_points(LINE, plane_elevation, georef, max_spacing_m=0.0)
    with pytest.raises(ValueError, match="search_radius_m"):
        lift_points(LINE, plane_elevation, georef, search_radius_m=-1.0)
    with pytest.raises(ValueError, match="points_2d: point 1 is not finite"):
        lift_points([[0.0, 0.0], [np.nan, 1.0]], plane_elevation, georef)
