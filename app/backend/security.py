"""Password hashing (standard-library scrypt) and opaque login tokens."""

import base64
import functools
import hashlib
import hmac
import logging
import secrets

logger = logging.getLogger(__name__)

SCRYPT_R = 8
SCRYPT_P = 1
SCRYPT_DKLEN = 32
SALT_BYTES = 16
TOKEN_BYTES = 32


def _b64(data: bytes) -> str:
    """URL-safe base64 without padding."""
    return base64.urlsafe_b64encode(data).decode("ascii").rstrip("=")


def _unb64(text: str) -> bytes:
    """Inverse of `_b64`."""
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def hash_password(password: str, *, n: int) -> str:
    """`scrypt$n$r$p$salt$digest` with a random salt; the cost is stored so it can be raised later."""
    salt = secrets.token_bytes(SALT_BYTES)
    digest = hashlib.scrypt(
        password.encode("utf-8"), salt=salt, n=n, r=SCRYPT_R, p=SCRYPT_P, dklen=SCRYPT_DKLEN
    )
    return f"scrypt${n}${SCRYPT_R}${SCRYPT_P}${_b64(salt)}${_b64(digest)}"


@functools.cache
def dummy_hash(n: int) -> str:
    """A hash of a random password at cost `n`: checking a login of an unknown user against it costs what
    checking a real user's password costs, so the answer time does not tell which user names exist."""
    return hash_password(secrets.token_urlsafe(TOKEN_BYTES), n=n)


def verify_password(password: str, stored: str) -> bool:
    """Whether `password` matches a hash from `hash_password`, compared in constant time."""
    try:
        scheme, n, r, p, salt, digest = stored.split("$")
        if scheme != "scrypt":
            return False
        expected = _unb64(digest)
        actual = hashlib.scrypt(
            password.encode("utf-8"), salt=_unb64(salt), n=int(n), r=int(r), p=int(p), dklen=len(expected)
        )
    except ValueError:
        logger.warning("unreadable password hash")
        return False
    return hmac.compare_digest(actual, expected)


def new_token() -> str:
    """A fresh opaque bearer token (256 random bits)."""
    return secrets.token_urlsafe(TOKEN_BYTES)


def token_digest(token: str) -> str:
    """SHA-256 of a token: what the database stores and looks up."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()
