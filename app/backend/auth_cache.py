"""A per-app cache of resolved login tokens: most requests check their token without a database query and
without a worker-thread hop (both cost more than the rest of a small request).

A token's user is read again from the database at most every `AUTH_CACHE_TTL_S` seconds (environment variable
CAMA_AUTH_CACHE_TTL_S; 0 turns the cache off), and the token's expiry is checked on every request. Through the
API users do not change once created (no deactivation or role change), and the one change to tokens, logout,
goes through `revoke`: the token leaves the cache at once and cannot be cached again by a request that read it
from the database just before it was deleted. A change made directly in the database (or a logout through another
server process on the same database) takes effect within the TTL. Unknown tokens are never cached, so junk
tokens cannot fill it.
"""

import logging
import os
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime

from app.backend.clock import as_utc, utc_now
from app.backend.models import User
from app.backend.security import token_digest

logger = logging.getLogger(__name__)

AUTH_CACHE_TTL_S = float(os.environ.get("CAMA_AUTH_CACHE_TTL_S", "10"))
"""How long a resolved token is trusted without asking the database again (seconds)."""
MAX_ENTRIES = 10_000
"""The cache is emptied when it would grow past this many tokens."""


@dataclass(frozen=True)
class CachedToken:
    """A token's user (detached, read-only), the token's expiry and when the database was asked."""

    user: User
    expires_at: datetime
    fetched_at: float


@dataclass
class TokenCache:
    """Token digest -> `CachedToken`, thread-safe."""

    ttl_s: float = AUTH_CACHE_TTL_S
    entries: dict[str, CachedToken] = field(default_factory=dict)
    revoked: dict[str, float] = field(default_factory=dict)
    """Digests of tokens revoked within the TTL, with when: never cached again."""
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __post_init__(self) -> None:
        """Reject a negative TTL (a bad CAMA_AUTH_CACHE_TTL_S), naming the variable."""
        if not self.ttl_s >= 0:
            raise ValueError(f"CAMA_AUTH_CACHE_TTL_S: must be >= 0, got {self.ttl_s}")

    def get(self, token: str) -> User | None:
        """The token's user when it was resolved within the TTL and the token has not expired."""
        with self.lock:
            entry = self.entries.get(token_digest(token))
        if entry is None or time.monotonic() - entry.fetched_at > self.ttl_s:
            return None
        return entry.user if as_utc(entry.expires_at) > utc_now() else None

    def put(self, token: str, user: User, expires_at: datetime) -> None:
        """Remember a token resolved from the database just now (nothing when the TTL is 0)."""
        if self.ttl_s <= 0:
            return
        digest = token_digest(token)
        with self.lock:
            if digest in self.revoked:
                return
            if len(self.entries) >= MAX_ENTRIES:
                self.entries.clear()
            self.entries[digest] = CachedToken(user, expires_at, time.monotonic())

    def revoke(self, token: str) -> None:
        """Forget a token deleted from the database (logout), and refuse to cache it for the next TTL."""
        digest = token_digest(token)
        now = time.monotonic()
        with self.lock:
            self.entries.pop(digest, None)
            self.revoked = {key: at for key, at in self.revoked.items() if now - at <= self.ttl_s}
            self.revoked[digest] = now
