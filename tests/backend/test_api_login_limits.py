"""Login hardening (issue 21.6): failed logins limited per user name and per address with `Retry-After`, the same
scrypt work for unknown users, and logout revoking the token at once (through the auth cache)."""

import hashlib
from collections.abc import Callable
from datetime import timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.auth_cache import TokenCache
from app.backend.clock import utc_now
from app.backend.config import Settings
from app.backend.login_limit import LoginLimiter
from app.backend.models import User
from tests.backend.backend_helpers import PASSWORD, login


class FakeClock:
    """A monotonic clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(client: TestClient, settings: Settings) -> FakeClock:
    """The app's login limiter on a hand-moved clock, with the limits of `settings`."""
    fake = FakeClock()
    client.app.state.login_limiter = LoginLimiter.from_settings(settings, clock=fake)  # type: ignore[attr-defined]
    return fake


def attempt(client: TestClient, username: str, password: str) -> Any:
    return client.post("/api/auth/login", json={"username": username, "password": password})


def test_failed_logins_of_a_user_name_are_limited_with_retry_after(
    client: TestClient, settings: Settings, clock: FakeClock
) -> None:
    window_s = settings.login_window_s
    for _ in range(settings.login_max_failures):
        assert attempt(client, "root", "wrong").status_code == 401
        clock.now += 1.0
    limited = attempt(client, "root", PASSWORD)  # even the right password waits: guessing stops here
    assert limited.status_code == 429, limited.text
    first_failure = 1000.0
    assert int(limited.headers["retry-after"]) == int(first_failure + window_s - clock.now)
    assert attempt(client, "someone-else", "wrong").status_code == 401  # other names are not locked out
    clock.now = first_failure + window_s + 0.5  # the oldest failure left the window: one more try
    assert attempt(client, "root", PASSWORD).status_code == 200


def test_a_success_clears_the_user_names_failures(
    client: TestClient, settings: Settings, clock: FakeClock
) -> None:
    for _ in range(settings.login_max_failures - 1):
        assert attempt(client, "root", "wrong").status_code == 401
    assert attempt(client, "root", PASSWORD).status_code == 200
    for _ in range(settings.login_max_failures - 1):
        assert attempt(client, "root", "wrong").status_code == 401
    assert attempt(client, "root", PASSWORD).status_code == 200


def test_failed_logins_from_one_address_are_limited_across_user_names(
    client: TestClient, settings: Settings, clock: FakeClock
) -> None:
    for index in range(settings.login_max_failures_per_address):
        assert attempt(client, f"guess{index}", "wrong").status_code == 401
    limited = attempt(client, "root", PASSWORD)
    assert limited.status_code == 429 and int(limited.headers["retry-after"]) >= 1, limited.text
    clock.now += settings.login_window_s
    assert attempt(client, "root", PASSWORD).status_code == 200


def test_limits_are_settings_read_from_the_environment() -> None:
    env = {
        "CAMA_LOGIN_MAX_FAILURES": "3",
        "CAMA_LOGIN_MAX_FAILURES_PER_ADDRESS": "9",
        "CAMA_LOGIN_WINDOW_S": "60",
    }
    settings = Settings.from_env(env)
    assert (
        settings.login_max_failures,
        settings.login_max_failures_per_address,
        settings.login_window_s,
    ) == (
        3,
        9,
        60.0,
    )
    with pytest.raises(ValueError, match="CAMA_LOGIN_WINDOW_S"):
        Settings.from_env({"CAMA_LOGIN_WINDOW_S": "0"})


def test_the_limiter_forgets_failures_older_than_the_window() -> None:
    fake = FakeClock()
    limiter = LoginLimiter(max_failures=2, max_failures_per_address=100, window_s=10.0, clock=fake)
    limiter.record_failure("a", "1.2.3.4")
    fake.now += 6.0
    limiter.record_failure("a", "1.2.3.4")
    assert limiter.retry_after_s("a", "1.2.3.4") == 4
    fake.now += 4.5
    assert limiter.retry_after_s("a", "1.2.3.4") is None
    fake.now += 10.0
    assert limiter.retry_after_s("a", "1.2.3.4") is None
    assert limiter.failures == {}  # expired names and addresses are dropped, not kept forever


def scrypt_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The `n` of every scrypt call from now on (the real function still runs)."""
    calls: list[int] = []
    real: Callable[..., bytes] = hashlib.scrypt

    def spy(password: bytes, **options: Any) -> bytes:
        calls.append(int(options["n"]))
        return real(password, **options)

    monkeypatch.setattr(hashlib, "scrypt", spy)
    return calls


def test_an_unknown_user_costs_the_same_scrypt_work_as_a_wrong_password(
    client: TestClient, settings: Settings, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = scrypt_calls(monkeypatch)
    assert attempt(client, "root", "wrong").status_code == 401
    real_user = list(calls)
    calls.clear()
    assert attempt(client, "nobody", "wrong").status_code == 401
    assert calls == real_user == [settings.scrypt_n]


def test_logout_revokes_the_token_at_once_even_when_cached(client: TestClient) -> None:
    first, second = login(client, "root"), login(client, "root")
    assert client.get("/api/auth/me", headers=first).status_code == 200  # now in the auth cache
    assert client.post("/api/auth/logout", headers=first).status_code == 204
    refused = client.get("/api/auth/me", headers=first)
    assert refused.status_code == 401, refused.text
    assert client.post("/api/auth/logout", headers=first).status_code == 401
    assert client.get("/api/auth/me", headers=second).status_code == 200  # other sessions stay
    assert client.post("/api/auth/logout").status_code == 401


def test_a_revoked_token_is_not_cached_again_by_a_request_that_read_it_before() -> None:
    cache = TokenCache(ttl_s=60.0)
    user = User(id=1, username="u", role="admin", password_hash="x", is_active=True)
    expires_at = utc_now() + timedelta(hours=1)
    cache.put("token", user, expires_at)
    assert cache.get("token") is user
    cache.revoke("token")
    assert cache.get("token") is None
    cache.put("token", user, expires_at)  # a database lookup that raced the logout
    assert cache.get("token") is None
