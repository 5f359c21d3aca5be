"""Backend settings: a frozen dataclass read from `CAMA_*` environment variables (no settings built at import)."""

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

logger = logging.getLogger(__name__)

DEFAULT_TOKEN_TTL_S = 12 * 3600
DEFAULT_MAX_PAYLOAD_BYTES = 8 * 1024 * 1024
DEFAULT_EXTENT_MARGIN_M = 50.0
DEFAULT_SCRYPT_N = 2**14


@dataclass(frozen=True)
class Settings:
    """Everything the backend needs to start; build with `Settings.from_env()` or directly in tests."""

    data_dir: Path = field(default_factory=lambda: Path("data/backend"))
    """Folder for the embedded SQLite database and other server state."""
    database_url: str = ""
    """SQLAlchemy URL; empty means `sqlite:///<data_dir>/cama.db`. PostgreSQL works by URL."""
    token_ttl_s: int = DEFAULT_TOKEN_TTL_S
    """How long a login token stays valid, in seconds."""
    max_payload_bytes: int = DEFAULT_MAX_PAYLOAD_BYTES
    """Largest request body accepted; larger ones get 413."""
    extent_margin_m: float = DEFAULT_EXTENT_MARGIN_M
    """How far (metres) outside the site's raster extent a vertex may lie before it is rejected."""
    scrypt_n: int = DEFAULT_SCRYPT_N
    """scrypt cost for new password hashes (a power of 2); stored with each hash."""
    admin_username: str = ""
    """When set with `admin_password` and the database has no users, this admin is created on start."""
    admin_password: str = ""

    def __post_init__(self) -> None:
        """Validate the fields so that a bad environment fails at start, naming the variable."""
        if self.token_ttl_s <= 0:
            raise ValueError(f"CAMA_TOKEN_TTL_S: must be positive, got {self.token_ttl_s}")
        if self.max_payload_bytes <= 0:
            raise ValueError(f"CAMA_MAX_PAYLOAD_BYTES: must be positive, got {self.max_payload_bytes}")
        if not self.extent_margin_m >= 0:
            raise ValueError(f"CAMA_EXTENT_MARGIN_M: must be >= 0, got {self.extent_margin_m}")
        if self.scrypt_n < 2 or self.scrypt_n & (self.scrypt_n - 1):
            raise ValueError(f"scrypt_n: must be a power of 2 >= 2, got {self.scrypt_n}")
        if bool(self.admin_username) != bool(self.admin_password):
            raise ValueError("CAMA_ADMIN_USERNAME and CAMA_ADMIN_PASSWORD: set both or neither")

    @property
    def resolved_database_url(self) -> str:
        """The database URL, defaulting to a SQLite file in `data_dir`."""
        return self.database_url or f"sqlite:///{Path(self.data_dir).resolve() / 'cama.db'}"

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None, **overrides: object) -> "Settings":
        """Read `CAMA_DATABASE_URL`, `CAMA_DATA_DIR`, `CAMA_TOKEN_TTL_S`, `CAMA_MAX_PAYLOAD_BYTES`, ...; overrides win."""
        env = os.environ if environ is None else environ
        values: dict[str, object] = {}
        for name, convert in _ENV_FIELDS.items():
            key = f"CAMA_{name.upper()}"
            if key in env and env[key] != "":
                try:
                    values[name] = convert(env[key])
                except ValueError as error:
                    raise ValueError(f"{key}: invalid value {env[key]!r}: {error}") from error
        values.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**values)  # type: ignore[arg-type]


_ENV_FIELDS: dict[str, type] = {
    "data_dir": Path,
    "database_url": str,
    "token_ttl_s": int,
    "max_payload_bytes": int,
    "extent_margin_m": float,
    "admin_username": str,
    "admin_password": str,
}
