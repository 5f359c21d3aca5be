"""The `/api` router: every resource router of the backend."""

from fastapi import APIRouter

from app.backend.api.routes import (
    cameras,
    elements,
    issues,
    jobs,
    login,
    quality,
    queues,
    rasters,
    reprojection,
    review,
    sites,
    users,
)

api_router = APIRouter(prefix="/api")
# Routes are matched in order: the element routes, hit by every edit, come first.
for module in (elements, review, login, users, sites):
    api_router.include_router(module.router)
for module in (rasters, quality, cameras, reprojection):
    api_router.include_router(module.router)
for module in (queues, issues):
    api_router.include_router(module.router)
api_router.include_router(jobs.router)
