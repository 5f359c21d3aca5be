"""Login: trade a username and password (JSON or form-encoded) for a bearer token."""

import json
import logging
from urllib.parse import parse_qs

from fastapi import APIRouter, HTTPException, Request, status
from pydantic import ValidationError
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from app.backend import crud
from app.backend.api.deps import CurrentUser, SessionDep, SettingsDep
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
    except ValidationError as error:
        raise HTTPException(
            status_code=422, detail=error.errors(include_url=False, include_context=False)
        ) from None


def _issue(session: Session, credentials: LoginRequest, ttl_s: int) -> TokenPublic | None:
    """A new token for valid credentials, else None (scrypt and the database: run in a worker thread)."""
    user = crud.authenticate(session=session, username=credentials.username, password=credentials.password)
    if user is None:
        return None
    token, expires_at = crud.issue_token(session=session, user=user, ttl_s=ttl_s)
    return TokenPublic(access_token=token, expires_at=expires_at)


@router.post("/login", response_model=TokenPublic, openapi_extra=LOGIN_BODY)
async def login(request: Request, session: SessionDep, settings: SettingsDep) -> TokenPublic:
    """Check the credentials and issue a token valid for the configured time. The password hash is checked
    in a worker thread: scrypt takes tens of milliseconds, which would stall every other request on the
    event loop."""
    credentials = await _read_credentials(request)
    issued = await run_in_threadpool(_issue, session, credentials, settings.token_ttl_s)
    if issued is None:
        raise HTTPException(status_code=status.HTTP_401_UNAUTHORIZED, detail="wrong username or password")
    return issued


@router.get("/me", response_model=UserPublic)
def me(user: CurrentUser) -> UserPublic:
    """The logged-in user."""
    return UserPublic.model_validate(user)
