"""Limits on failed logins, per user name and per client address, over a sliding window (in memory, per app).

After `max_failures` failed logins of one user name (or `max_failures_per_address` from one client address)
within `window_s` seconds, further logins of that name (from that address) are refused with 429 and a
`Retry-After` until the oldest counted failure leaves the window; refused attempts are not checked, so they cost
no password hashing and count for nothing. A successful login clears its user name's failures (not its
address's: an attacker's own account must not reset the address count). Behind a reverse proxy every client
has the proxy's address, so the address limit then applies to all of them together.
"""

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from app.backend.config import Settings

logger = logging.getLogger(__name__)

MAX_KEYS = 100_000
"""Most user names and addresses remembered; past it the expired ones are dropped, then the oldest."""


@dataclass
class LoginLimiter:
    """Failed-login times per user name and per client address; thread-safe."""

    max_failures: int
    max_failures_per_address: int
    window_s: float
    clock: Callable[[], float] = time.monotonic
    """Seconds, monotonic; tests pass their own."""
    failures: dict[tuple[str, str], deque[float]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    @classmethod
    def from_settings(cls, settings: Settings, clock: Callable[[], float] = time.monotonic) -> "LoginLimiter":
        """The limits of `settings` (CAMA_LOGIN_MAX_FAILURES, ..._PER_ADDRESS, CAMA_LOGIN_WINDOW_S)."""
        return cls(
            max_failures=settings.login_max_failures,
            max_failures_per_address=settings.login_max_failures_per_address,
            window_s=settings.login_window_s,
            clock=clock,
        )

    def _limits(self, username: str, address: str) -> tuple[tuple[tuple[str, str], int], ...]:
        return (("user", username), self.max_failures), (("address", address), self.max_failures_per_address)

    def _recent(self, key: tuple[str, str], now: float) -> deque[float]:
        """The failures of `key` still inside the window (older ones dropped); call with the lock held."""
        times = self.failures.get(key)
        if times is None:
            return deque()
        while times and times[0] <= now - self.window_s:
            times.popleft()
        if not times:
            del self.failures[key]
        return times

    def retry_after_s(self, username: str, address: str) -> int | None:
        """Whole seconds until `username` may try again from `address`; None when it may now."""
        now = self.clock()
        waits = []
        with self.lock:
            for key, limit in self._limits(username, address):
                times = self._recent(key, now)
                if len(times) >= limit:
                    waits.append(times[-limit] + self.window_s - now)
        return max(1, math.ceil(max(waits))) if waits else None

    def record_failure(self, username: str, address: str) -> None:
        """Count a failed login of `username` from `address`."""
        now = self.clock()
        with self.lock:
            for key, _limit in self._limits(username, address):
                self.failures.setdefault(key, deque()).append(now)
            if len(self.failures) > MAX_KEYS:
                self._shrink(now)

    def record_success(self, username: str) -> None:
        """A successful login clears the user name's failures."""
        with self.lock:
            self.failures.pop(("user", username), None)

    def _shrink(self, now: float) -> None:
        """Drop expired keys, then the oldest ones, down to half of `MAX_KEYS` (lock held)."""
        for key in list(self.failures):
            self._recent(key, now)
        excess = len(self.failures) - MAX_KEYS // 2
        if excess > 0:
            for key in list(self.failures)[:excess]:
                del self.failures[key]
            logger.warning(
                "login limiter: forgot %d user names and addresses (more than %d)", excess, MAX_KEYS
            )
