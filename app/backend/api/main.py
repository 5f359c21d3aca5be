"""The `/api` router: every resource router of the backend."""

from fastapi import APIRouter

from app.backend.api.routes import elements, login, review, sites, users

api_router = APIRouter(prefix="/api")
for module in (login, users, sites, elements, review):
    api_router.include_router(module.router)
