"""Domain errors raised by crud and mapped to HTTP responses by `install_error_handlers`."""

import json
import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.utils import is_body_allowed_for_status_code
from starlette.exceptions import HTTPException as StarletteHTTPException

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


class SafeJSONResponse(JSONResponse):
    """A JSON answer that always encodes: non-ASCII text is escaped (`\\uXXXX`), so a lone surrogate that came
    in with a request (JSON allows `"\\ud800"`) goes out escaped instead of failing the UTF-8 encoding."""

    def render(self, content: Any) -> bytes:
        return json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":")).encode("ascii")


def plain_errors(errors: Any) -> list[dict[str, Any]]:
    """Validation errors without the offending inputs: an input may be a password, a server path, NaN (not
    encodable as JSON) or a lone surrogate; `loc`, `msg` and `type` say what is wrong."""
    return [
        {"loc": list(item.get("loc", [])), "msg": str(item.get("msg", "")), "type": str(item.get("type", ""))}
        for item in errors
    ]


def install_error_handlers(app: FastAPI) -> None:
    """Register the JSON responses for the domain errors."""

    async def not_found(_request: Request, error: Exception) -> JSONResponse:
        return SafeJSONResponse(status_code=404, content={"detail": str(error).strip("'\"")})

    async def conflict(_request: Request, error: Exception) -> JSONResponse:
        body: dict[str, Any] = {"detail": str(error)}
        if isinstance(error, ConflictError) and error.current is not None:
            body["current"] = error.current
        return SafeJSONResponse(status_code=409, content=body)

    async def invalid(_request: Request, error: Exception) -> JSONResponse:
        field = error.field if isinstance(error, InvalidInputError) else "body"
        detail = [{"loc": ["body", field], "msg": str(error), "type": "value_error"}]
        return SafeJSONResponse(status_code=422, content={"detail": detail})

    async def forbidden(_request: Request, error: Exception) -> JSONResponse:
        return SafeJSONResponse(status_code=403, content={"detail": str(error)})

    async def validation(_request: Request, error: Exception) -> JSONResponse:
        errors = error.errors() if isinstance(error, RequestValidationError) else []
        return SafeJSONResponse(status_code=422, content={"detail": plain_errors(errors)})

    async def http_error(_request: Request, error: Exception) -> Response:
        if not isinstance(error, StarletteHTTPException):
            raise error
        if not is_body_allowed_for_status_code(error.status_code):
            return Response(status_code=error.status_code, headers=error.headers)
        return SafeJSONResponse(
            {"detail": error.detail}, status_code=error.status_code, headers=error.headers
        )

    async def too_deep(request: Request, _error: Exception) -> JSONResponse:
        logger.warning(
            "%s %s: nested too deeply to handle (RecursionError)", request.method, request.url.path
        )
        return SafeJSONResponse(status_code=400, content={"detail": "body: nested too deeply"})

    app.add_exception_handler(RequestValidationError, validation)
    app.add_exception_handler(StarletteHTTPException, http_error)
    app.add_exception_handler(RecursionError, too_deep)
    app.add_exception_handler(NotFoundError, not_found)
    app.add_exception_handler(ForbiddenError, forbidden)
    app.add_exception_handler(ConflictError, conflict)
    app.add_exception_handler(InvalidInputError, invalid)
