"""Focusing the 3D review on the element the editor's link names, and the road mesh's matte material."""

import json
import socket
import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
import viser

from annotations.schema import Georeference
from app.viewer.content import Surface, local_frame_of
from app.viewer.focus import FOCUS_OFFSET_M, element_in_url, focus_client, requested_element
from app.viewer.review import show_vectors
from app.viewer.scene import ReviewScene, matte
from app.viewer.sources import ViewElement


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _flat_surface(z_m: float = 3.0) -> Surface:
    """A 10 m x 10 m surface at a constant height (global x 100..110, y 200..210)."""
    geo = Georeference(
        site_origin_xy=(0.0, 0.0), origin_xy=(100.05, 209.95), resolution=0.1, width=100, height=100
    )
    elevation = np.full(geo.shape, z_m)
    return Surface(elevation, np.zeros(geo.shape, bool), geo, Path("."), True)


class _ListSource:
    def __init__(self, elements: list[ViewElement]) -> None:
        self.elements = elements

    def load(self) -> list[ViewElement]:
        return self.elements


class _Camera:
    """Records what the focus sets; `report` plays the browser's first camera message."""

    def __init__(self) -> None:
        self.callbacks: list[Callable[[_Camera], None]] = []
        self.position: np.ndarray | None = None
        self.look_at: np.ndarray | None = None

    def on_update(self, callback: Callable[["_Camera"], None]) -> Callable[["_Camera"], None]:
        self.callbacks.append(callback)
        return callback

    def report(self) -> None:
        for callback in self.callbacks:
            callback(self)


class _Client:
    def __init__(self) -> None:
        self.client_id = 99
        self.camera = _Camera()
        self.notes: list[str] = []

    def add_notification(self, title: str, body: str, **_: Any) -> None:
        self.notes.append(title)


@pytest.fixture()
def scene() -> Iterator[ReviewScene]:
    server = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    surface = _flat_surface()
    divider = ViewElement("42", "divider", "proposed", 1, np.array([[102.0, 205.0], [108.0, 205.0]]))
    yield show_vectors(ReviewScene(server, local_frame_of(surface), surface), _ListSource([divider]))
    server.stop()


@pytest.mark.parametrize(
    ("path", "expected"),
    [("/?element=42", "42"), ("/?x=1&element=e7", "e7"), ("/", None), ("/?element=", None), ("", None)],
)
def test_the_element_comes_from_the_websocket_query(path: str, expected: str | None) -> None:
    assert element_in_url(path) == expected


def test_focus_selects_and_looks_at_the_element_once(scene: ReviewScene) -> None:
    client = _Client()
    assert focus_client(scene, client, "42")  # type: ignore[arg-type]
    assert scene.selected == "42" and "Element 42" in scene._panel.content
    centre = scene.element_centre("42")
    assert centre is not None
    assert np.allclose(centre[:2], [0.0, 0.0], atol=1e-6) and abs(centre[2]) < 0.2  # the frame's origin
    client.camera.report()
    assert client.camera.look_at is not None and client.camera.position is not None
    assert np.allclose(client.camera.look_at, centre) and np.allclose(
        client.camera.position, centre + FOCUS_OFFSET_M
    )
    client.camera.look_at = np.zeros(3)
    client.camera.report()  # the user moves afterwards: the camera is left alone
    assert np.allclose(client.camera.look_at, 0.0)


def test_an_unknown_element_is_named_to_that_browser(scene: ReviewScene) -> None:
    client = _Client()
    assert not focus_client(scene, client, "7")  # type: ignore[arg-type]
    assert client.notes == ["Element 7 is not in the 3D view"] and scene.selected is None
    assert client.camera.callbacks == []


def test_without_viser_internals_no_element_is_requested(scene: ReviewScene) -> None:
    assert requested_element(scene.server, _Client()) is None  # type: ignore[arg-type]


def test_the_mesh_is_exported_matte_with_linear_colours() -> None:
    mesh = trimesh.Trimesh(
        vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
        faces=[[0, 1, 2]],
        vertex_colors=[[255, 255, 255], [128, 128, 128], [0, 0, 0]],
        process=False,
    )
    glb = matte(mesh).export(file_type="glb")
    length = struct.unpack("<I", glb[12:16])[0]
    document = json.loads(glb[20 : 20 + length])
    pbr = document["materials"][0]["pbrMetallicRoughness"]
    assert pbr["metallicFactor"] == 0.0 and pbr["roughnessFactor"] == 1.0
    assert "COLOR_0" in document["meshes"][0]["primitives"][0]["attributes"]
    colors = matte(mesh).visual.vertex_attributes["color"]  # type: ignore[union-attr]
    assert colors[:, 0].tolist() == [255, 55, 0]  # sRGB 128 is linear 0.216
