"""Domain errors raised by crud and mapped to HTTP responses by `install_error_handlers`."""

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

logger = logging.getLogger(__name__)


class NotFoundError(LookupError):
    """A site, element, user or version that does not exist (404)."""


class ForbiddenError(PermissionError):
    """The user's role may not do this (403)."""


class ConflictError(Exception):
    """A stale version or an invalid state change (409); `current` is the element as stored now."""

    def __init__(self, message: str, current: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.current = current


class InvalidInputError(ValueError):
    """Input that parses but makes no sense for this site, e.g. vertices far outside it (422)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


def _plain(item: Any) -> dict[str, Any]:
    """One validation error without the offending input, which may be NaN and so not encodable as JSON."""
    return {
        "loc": list(item.get("loc", [])),
        "msg": str(item.get("msg", "")),
        "type": str(item.get("type", "")),
    }


def install_error_handlers(app: FastAPI) -> None:
    """Register the JSON responses for the domain errors."""

    async def not_found(_request: Request, error: Exception) -> JSONResponse:
        return JSONResponse(status_code=404, content={"detail": str(error).strip("'\"")})

    async def conflict(_request: Request, error: Exception) -> JSONResponse:
        body: dict[str, Any] = {"detail": str(error)}
        if isinstance(error, ConflictError) and error.current is not None:
            body["current"] = error.current
        return JSONResponse(status_code=409, content=body)

    async def invalid(_request: Request, error: Exception) -> JSONResponse:
        field = error.field if isinstance(error, InvalidInputError) else "body"
        detail = [{"loc": ["body", field], "msg": str(error), "type": "value_error"}]
        return JSONResponse(status_code=422, content={"detail": detail})

    async def forbidden(_request: Request, error: Exception) -> JSONResponse:
        return JSONResponse(status_code=403, content={"detail": str(error)})

    async def validation(_request: Request, error: Exception) -> JSONResponse:
        errors = error.errors() if isinstance(error, RequestValidationError) else []
        return JSONResponse(status_code=422, content={"detail": [_plain(item) for item in errors]})

    app.add_exception_handler(RequestValidationError, validation)
    app.add_exception_handler(NotFoundError, not_found)
    app.add_exception_handler(ForbiddenError, forbidden)
    app.add_exception_handler(ConflictError, conflict)
    app.add_exception_handler(InvalidInputError, invalid)
