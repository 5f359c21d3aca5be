"""Login: trade a username and password (JSON or form-encoded) for a bearer token; logout revokes it.

Failed logins are limited per user name and per client address (`app.backend.login_limit`, 429 with
`Retry-After`), and a refusal costs the same password hashing whether or not the user exists."""

import json
import logging
from typing import Annotated, Any
from urllib.parse import parse_qs

from fastapi import APIRouter, Depends, HTTPException, Request, Response, status
from fastapi.exceptions import RequestValidationError
from fastapi.security import HTTPAuthorizationCredentials
from pydantic import ValidationError
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from app.backend import crud
from app.backend.api.deps import CurrentUser, SessionDep, SettingsDep, bearer
from app.backend.auth_cache import TokenCache
from app.backend.config import Settings
from app.backend.crud.users import revoke_token
from app.backend.login_limit import LoginLimiter
from app.backend.schemas import LoginRequest, TokenPublic, UserPublic

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/auth", tags=["auth"])

LOGIN_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": LoginRequest.model_json_schema()},
            "application/x-www-form-urlencoded": {"schema": LoginRequest.model_json_schema()},
        },
    }
}
LIMITED: dict[int | str, dict[str, Any]] = {
    429: {"description": "Too many failed logins of this user name or from this address; see `Retry-After`."}
}


async def _read_credentials(request: Request) -> LoginRequest:
    """Parse the body as a form (OAuth2 password style) or JSON; 422 naming the problem."""
    body = await request.body()
    try:
        if request.headers.get("content-type", "").startswith("application/x-www-form-urlencoded"):
            form = parse_qs(body.decode("utf-8"), keep_blank_values=True)
            data = {key: form[key][0] for key in ("username", "password") if key in form}
        else:
            data = json.loads(body or b"null")
        return LoginRequest.model_validate(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise HTTPException(status_code=422, detail=f"body: unreadable login request: {error}") from None
    except RecursionError:
        raise HTTPException(status_code=400, detail="body: nested too deeply") from None
    except ValidationError as error:  # answered without the inputs: never echo a password
        raise RequestValidationError(
            [{**item, "loc": ("body", *item["loc"])} for item in error.errors(include_input=False)]
        ) from None


def _issue(session: Session, credentials: LoginRequest, settings: Settings) -> TokenPublic | None:
    """A new token for valid credentials, else None (scrypt and the database: run in a worker thread)."""
    user = crud.authenticate(
        session=session,
        username=credentials.username,
        password=credentials.password,
        scrypt_n=settings.scrypt_n,
    )
    if user is None:
        return None
    token, expires_at = crud.issue_token(session=session, user=user, ttl_s=settings.token_ttl_s)
    return TokenPublic(access_token=token, expires_at=expires_at)


@router.post("/login", response_model=TokenPublic, openapi_extra=LOGIN_BODY, responses=LIMITED)
async def login(request: Request, session: SessionDep, settings: SettingsDep) -> TokenPublic:
    """Check the credentials and issue a token valid for the configured time. After too many failures of the
    user name or from the client's address within the window (CAMA_LOGIN_*), 429 with `Retry-After`. The
    password hash is checked in a worker thread: scrypt takes tens of milliseconds, which would stall every
    other request on the event loop."""
    credentials = await _read_credentials(request)
    limiter: LoginLimiter = request.app.state.login_limiter
    address = request.client.host if request.client is not None else ""
    wait_s = limiter.retry_after_s(credentials.username, address)
    if wait_s is not None:
        raise HTTPException(
            status_code=status.HTTP_429_TOO_MANY_REQUESTS,
            detail=f"too many failed logins; try again in {wait_s} s",
            headers={"Retry-After": str(wait_s)},
        )
    issued = await run_in_threadpool(_issue, session, credentials, settings)
    if issued is None:
        limiter.record_failure(credentials.username, address)
        raise HTTPException(status_code=status.HTTP_401_UNAUTHORIZED, detail="wrong username or password")
    limiter.record_success(credentials.username)
    return issued


@router.post("/logout", status_code=status.HTTP_204_NO_CONTENT)
async def logout(
    request: Request,
    session: SessionDep,
    _user: CurrentUser,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> Response:
    """Revoke the bearer token of this request: it is refused from now on (log in again for a new one)."""
    if credentials is not None:  # always set: CurrentUser checked it
        await run_in_threadpool(lambda: revoke_token(session=session, token=credentials.credentials))
        cache: TokenCache = request.app.state.token_cache
        cache.revoke(credentials.credentials)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/me", response_model=UserPublic)
def me(user: CurrentUser) -> UserPublic:
    """The logged-in user."""
    return UserPublic.model_validate(user)
