"""Users and login tokens: create, authenticate, resolve a bearer token."""

import logging
from datetime import datetime, timedelta

from sqlalchemy import delete, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.backend.clock import as_utc, utc_now
from app.backend.errors import ConflictError
from app.backend.models import Token, User
from app.backend.security import dummy_hash, hash_password, new_token, token_digest, verify_password

logger = logging.getLogger(__name__)


def create_user(*, session: Session, username: str, password: str, role: str, scrypt_n: int) -> User:
    """Store a new user with a scrypt password hash; ConflictError when the name is taken."""
    user = User(
        username=username,
        role=role,
        password_hash=hash_password(password, n=scrypt_n),
        is_active=True,
        created_at=utc_now(),
    )
    session.add(user)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise ConflictError(f"username: {username!r} is already taken") from None
    logger.info("created user %s (%s)", username, role)
    return user


def list_users(*, session: Session) -> list[User]:
    """All users, oldest first."""
    return list(session.scalars(select(User).order_by(User.id)))


def ensure_admin(*, session: Session, username: str, password: str, scrypt_n: int) -> User | None:
    """Create the first admin when the database has no users yet (bootstrap without a CLI)."""
    if session.scalar(select(func.count()).select_from(User)):
        return None
    return create_user(session=session, username=username, password=password, role="admin", scrypt_n=scrypt_n)


def authenticate(*, session: Session, username: str, password: str, scrypt_n: int) -> User | None:
    """The active user with these credentials, or None. An unknown or inactive user's login costs the same
    scrypt work (a dummy hash at cost `scrypt_n`), so the time of a refusal does not tell which names exist."""
    user = session.scalar(select(User).where(User.username == username))
    matches = verify_password(password, user.password_hash if user is not None else dummy_hash(scrypt_n))
    if user is None or not user.is_active or not matches:
        return None
    return user


def revoke_token(*, session: Session, token: str) -> bool:
    """Delete a login token (logout); whether it existed."""
    result = session.execute(delete(Token).where(Token.token_hash == token_digest(token)))
    session.commit()
    return bool(getattr(result, "rowcount", 0))


def issue_token(*, session: Session, user: User, ttl_s: int) -> tuple[str, datetime]:
    """A new bearer token for `user` and its expiry; expired tokens of the user are dropped."""
    now = utc_now()
    session.execute(delete(Token).where(Token.user_id == user.id, Token.expires_at < now))
    token = new_token()
    expires_at = now + timedelta(seconds=ttl_s)
    session.add(Token(token_hash=token_digest(token), user_id=user.id, expires_at=expires_at))
    session.commit()
    return token, expires_at


def user_for_token(*, session: Session, token: str) -> tuple[User, datetime] | None:
    """The active user owning an unexpired token and the token's expiry, or None (in one query)."""
    row = session.execute(
        select(User, Token.expires_at)
        .join(Token, Token.user_id == User.id)
        .where(Token.token_hash == token_digest(token), User.is_active.is_(True))
    ).first()
    if row is None or as_utc(row.expires_at) <= utc_now():
        return None
    return row[0], row[1]
