"""The built browser editor (`app/frontend/dist`, made by the Vite build of the set-up step) at `/`, the
small settings the page reads on start (`/api/frontend/config`: where the 3D review is served), and the API docs
page at `/docs` with Swagger UI from the same build (`dist/docs`, from the swagger-ui-dist package: no CDN).

Only `index.html` and the hashed files under `assets/` are served; the page gets a strict Content-Security-Policy
(scripts from this origin only), so even a rendering mistake could not run injected script.
"""

import logging
from pathlib import Path

from fastapi import APIRouter
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse
from pydantic import BaseModel, Field

from app.backend.api.deps import SettingsDep
from app.backend.errors import NotFoundError

logger = logging.getLogger(__name__)
router = APIRouter()

DIST_DIR = Path(__file__).resolve().parents[3] / "frontend" / "dist"
"""Vite's output folder; built by `make` (the `frontend` target) before `demo` and `test`."""
ASSET_CACHE_CONTROL = "public, max-age=31536000, immutable"
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' blob: data:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)


def _index_file() -> Path:
    """The editor's page; 404 explaining how to build it when the build output is missing."""
    index = DIST_DIR / "index.html"
    if not index.is_file():
        raise NotFoundError(
            f"the editor is not built: {index} is missing; run `make setup` (npm ci + vite build)"
        )
    return index


class FrontendConfig(BaseModel):
    """What the editor needs to know about its surroundings (no secrets: read before logging in)."""

    review_url: str | None = Field(
        description="The viser 3D review's URL, or `:<port>` on the editor's host; null when none is served."
    )
    review_site_id: int | None = Field(
        description="The site the 3D review shows; null: it follows whichever site it was started on."
    )


@router.get("/api/frontend/config", response_model=FrontendConfig, tags=["frontend"])
def frontend_config(settings: SettingsDep) -> FrontendConfig:
    """Where the 3D review is served (`CAMA_REVIEW_URL`, set by `cama demo`), for the editor's link to it."""
    return FrontendConfig(review_url=settings.review_url or None, review_site_id=settings.review_site_id)


@router.get("/", response_class=FileResponse, include_in_schema=False)
def editor_page() -> FileResponse:
    """The single-page editor; it routes itself by URL hash and talks to `/api`."""
    headers = {"Content-Security-Policy": CONTENT_SECURITY_POLICY, "Cache-Control": "no-cache"}
    return FileResponse(_index_file(), media_type="text/html", headers=headers)


@router.get("/assets/{name}", response_class=FileResponse, include_in_schema=False)
def editor_asset(name: str) -> FileResponse:
    """A hashed script, style sheet or image of the build; names with path parts are refused."""
    assets = (DIST_DIR / "assets").resolve()
    path = (assets / name).resolve()
    if path.parent != assets or not path.is_file():
        raise NotFoundError(f"no editor asset {name!r}")
    return FileResponse(path, headers={"Cache-Control": ASSET_CACHE_CONTROL})


DOCS_ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "favicon-32x32.png")
"""Swagger UI's files the build copies to `dist/docs` (vite.config.js)."""


@router.get("/docs", response_class=HTMLResponse, include_in_schema=False)
def docs_page() -> HTMLResponse:
    """Swagger UI over `/openapi.json`, its script and style served from this server."""
    return get_swagger_ui_html(
        openapi_url="/openapi.json",
        title="CAMA Studio - API docs",
        swagger_js_url="/docs/swagger-ui-bundle.js",
        swagger_css_url="/docs/swagger-ui.css",
        swagger_favicon_url="/docs/favicon-32x32.png",
        swagger_ui_parameters={"validatorUrl": None},  # no online validator badge: nothing leaves this server
    )


@router.get("/docs/{name}", response_class=FileResponse, include_in_schema=False)
def docs_asset(name: str) -> FileResponse:
    """One of Swagger UI's files; 404 explaining how to build them when the build output is missing."""
    if name not in DOCS_ASSETS:
        raise NotFoundError(f"no docs asset {name!r}")
    path = DIST_DIR / "docs" / name
    if not path.is_file():
        raise NotFoundError(
            f"the API docs page is not built: run `make setup` (npm ci + vite build) for {name}"
        )
    return FileResponse(path, headers={"Cache-Control": "public, max-age=86400"})
