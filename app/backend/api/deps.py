"""Request dependencies: settings, a database session, the current user and role checks."""

import logging
import threading
from collections.abc import AsyncIterator, Callable, Coroutine
from datetime import datetime
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from app.backend import crud
from app.backend.auth_cache import TokenCache
from app.backend.config import Settings
from app.backend.crud.quality import LintCache
from app.backend.models import User
from app.backend.schemas import MAX_ID

logger = logging.getLogger(__name__)

bearer = HTTPBearer(auto_error=False, description="Token from POST /api/auth/login.")


async def get_settings(request: Request) -> Settings:
    """The settings the app was created with (async: no I/O, so no worker-thread hop)."""
    settings: Settings = request.app.state.settings
    return settings


async def get_session(request: Request) -> AsyncIterator[Session]:
    """One database session per request, closed afterwards.

    Async because making a session does no I/O (its connection is checked out by the first query, in the
    endpoint's worker thread); a sync generator would cost two worker-thread hops per request. Closing returns
    the connection to the pool (a rollback of a finished transaction: no disk, one loopback round-trip at most
    on PostgreSQL)."""
    with request.app.state.sessionmaker() as session:
        yield session


IdPath = Annotated[int, Path(ge=1, le=MAX_ID)]
VersionPath = Annotated[int, Path(ge=1, le=MAX_ID)]

SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]


def _lookup_token(sessions: sessionmaker[Session], token: str) -> tuple[User, datetime] | None:
    """The token's user and expiry from the database (in a worker thread), detached from its session."""
    with sessions() as session:
        return crud.user_for_token(session=session, token=token)


async def _user_for_token(request: Request, token: str) -> User | None:
    """The token's user from the app's token cache, or from the database (then cached)."""
    cache: TokenCache = request.app.state.token_cache
    user = cache.get(token)
    if user is None:
        found = await run_in_threadpool(_lookup_token, request.app.state.sessionmaker, token)
        if found is not None:
            cache.put(token, *found)
            user = found[0]
    return user


async def get_current_user(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> User:
    """The user owning the bearer token; 401 when it is missing, unknown or expired."""
    user = None
    if credentials is not None and credentials.scheme.lower() == "bearer":
        user = await _user_for_token(request, credentials.credentials)
    if user is None:
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="not authenticated: send 'Authorization: Bearer <token>' from POST /api/auth/login",
            headers={"WWW-Authenticate": "Bearer"},
        )
    return user


CurrentUser = Annotated[User, Depends(get_current_user)]


def require_role(*roles: str) -> Callable[[User], Coroutine[None, None, User]]:
    """A dependency that lets only users with one of `roles` through (403 otherwise)."""

    async def check(user: CurrentUser) -> User:
        if user.role not in roles:
            raise HTTPException(
                status_code=status.HTTP_403_FORBIDDEN,
                detail=f"role {user.role!r} may not do this; needs one of {sorted(roles)}",
            )
        return user

    return check


AnyUser = CurrentUser
LeadUser = Annotated[User, Depends(require_role("lead", "admin"))]
AdminUser = Annotated[User, Depends(require_role("admin"))]


_LINT_CACHE_LOCK = threading.Lock()


async def get_lint_cache(request: Request) -> LintCache:
    """The app's lint cache, made on first use (one per app, so tests and servers never share one)."""
    with _LINT_CACHE_LOCK:
        cache = getattr(request.app.state, "lint_cache", None)
        if cache is None:
            budget_s = request.app.state.settings.lint_budget_s
            cache = request.app.state.lint_cache = LintCache(budget_s=budget_s)
    return cache


LintCacheDep = Annotated[LintCache, Depends(get_lint_cache)]
