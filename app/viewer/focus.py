"""Open the 3D review on one element: the editor's "3D review" link names the selected element.

viser's page does not tell the server its own URL, but it connects its websocket to the URL given by its
`?websocket=` parameter. The editor's link is therefore
`http://host:port/?websocket=ws://host:port/?element=<id>`: the element id arrives in the websocket request's
query, which the server reads when the client connects (through viser's connection table, a private attribute
of the pinned viser version; without it the link still opens the review, just unfocused). The element is then
selected (shown in the panel) and that browser's camera is moved to look down on it.
"""

import logging
import threading
from collections.abc import Callable
from urllib.parse import parse_qs, urlsplit

import numpy as np
import viser

from app.viewer.scene import ReviewScene

logger = logging.getLogger(__name__)

ELEMENT_PARAM = "element"
"""The websocket URL's query parameter naming the element to focus."""
FOCUS_OFFSET_M = np.array([0.0, -12.0, 18.0])
"""Camera position relative to the focused element's centre (view frame, z up): behind and above it."""


def element_in_url(url_path: str) -> str | None:
    """The element id of a websocket request path such as `/?element=42`; None when absent or empty."""
    values = parse_qs(urlsplit(url_path).query).get(ELEMENT_PARAM)
    return values[0] if values and values[0] else None


def requested_element(server: viser.ViserServer, client: viser.ClientHandle) -> str | None:
    """The element the client's websocket URL names, if viser lets us see that URL."""
    try:
        request = server._websock_server._live_connections[client.client_id].request
    except (AttributeError, KeyError):
        request = None
    if request is None:
        logger.debug("client %s: websocket URL not available", client.client_id)
        return None
    return element_in_url(str(request.path))


def focus_client(scene: ReviewScene, client: viser.ClientHandle, element_id: str) -> bool:
    """Select the element and, once the browser has reported its camera, look at it; False when not drawn."""
    centre = scene.element_centre(element_id)
    if centre is None:
        client.add_notification(
            f"Element {element_id} is not in the 3D view",
            "It may be deleted, on another site, or without elevation to lift it.",
            auto_close_seconds=8.0,
        )
        return False
    scene.select(element_id)
    moved = threading.Event()

    @client.camera.on_update
    def _(camera: viser.CameraHandle) -> None:
        if moved.is_set():
            return
        moved.set()
        camera.position = centre + FOCUS_OFFSET_M
        camera.look_at = centre

    return True


def focus_on_connect(scene: ReviewScene) -> Callable[[viser.ClientHandle], None]:
    """A connect callback that focuses each new client on the element its URL names."""

    def on_connect(client: viser.ClientHandle) -> None:
        element_id = requested_element(scene.server, client)
        if element_id is not None:
            logger.info("client %s asked for element %s", client.client_id, element_id)
            focus_client(scene, client, element_id)

    return on_connect
