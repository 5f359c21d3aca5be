"""The per-app token cache: a resolved token is served from memory within its TTL, never past its expiry;
unknown tokens are not cached; a TTL of 0 turns it off."""

import time
from datetime import timedelta

import pytest

from app.backend.auth_cache import TokenCache
from app.backend.clock import utc_now
from app.backend.models import User


def user(name: str = "ann") -> User:
    return User(
        id=1, username=name, role="annotator", password_hash="x", is_active=True, created_at=utc_now()
    )


def test_a_resolved_token_is_served_until_the_ttl_passes() -> None:
    cache = TokenCache(ttl_s=0.05)
    assert cache.get("t") is None
    cache.put("t", user(), utc_now() + timedelta(hours=1))
    cached = cache.get("t")
    assert cached is not None and cached.username == "ann"
    assert cache.get("other") is None
    time.sleep(0.06)
    assert cache.get("t") is None  # asked again from the database


def test_an_expired_token_is_refused_even_when_cached() -> None:
    cache = TokenCache(ttl_s=60.0)
    cache.put("t", user(), utc_now() - timedelta(seconds=1))
    assert cache.get("t") is None


def test_ttl_zero_caches_nothing_and_a_negative_ttl_is_refused() -> None:
    cache = TokenCache(ttl_s=0.0)
    cache.put("t", user(), utc_now() + timedelta(hours=1))
    assert cache.get("t") is None and cache.entries == {}
    with pytest.raises(ValueError, match="CAMA_AUTH_CACHE_TTL_S"):
        TokenCache(ttl_s=-1.0)
