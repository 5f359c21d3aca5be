"""Backend settings: a frozen dataclass read from `CAMA_*` environment variables (no settings built at import)."""

import logging
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

logger = logging.getLogger(__name__)

DEFAULT_TOKEN_TTL_S = 12 * 3600
DEFAULT_MAX_PAYLOAD_BYTES = 8 * 1024 * 1024
DEFAULT_EXTENT_MARGIN_M = 50.0
DEFAULT_SCRYPT_N = 2**14
DEFAULT_QA_SHARE = 0.1
DEFAULT_RETRAIN_STALL_S = 900.0
DEFAULT_LOGIN_MAX_FAILURES = 5
DEFAULT_LOGIN_MAX_FAILURES_PER_ADDRESS = 20
DEFAULT_LOGIN_WINDOW_S = 300.0
DEFAULT_MAX_ELEMENT_VERTICES = 10_000
DEFAULT_MAX_SITE_VERTICES = 500_000
DEFAULT_LINT_BUDGET_S = 2.0


_REVIEW_URL = re.compile(r"https?://[^\s/?#]+(/[^\s?#]*)?|:\d{1,5}")
"""An http(s) URL without query or fragment (the editor adds the query), or `:<port>`."""


def _paths(value: str) -> tuple[Path, ...]:
    """A list of folders separated by the OS path separator (`:` on Linux)."""
    return tuple(Path(part) for part in value.split(os.pathsep) if part)


VMA_MODELS = ("auto", "maptr", "masks")
"""The shipped networks a server's registry can be seeded from (`Settings.vma_model`)."""


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
    vma_registry: Path | None = None
    """VMA checkpoint registry (`models.vma.checkpoint`); retrain needs it, proposal refresh uses it (else the
    rule-based proposer), and its promoted version's calibration gives the pre-accept threshold."""
    vma_model: str = "auto"
    """Which shipped network seeds `DATA_DIR`'s registry when `vma_registry` is not set: `masks` (the element-mask
    network, whose geometry retraining changes, `DATA_DIR/vma-mask-registry`), `maptr` (the anchored MapTR-style
    model, `DATA_DIR/vma-registry`) or `auto`: masks, unless the data folder already holds a MapTR-style registry
    and no mask registry (a server started before the default changed keeps the versions its leads trained).
    A configured registry is used as it is, whichever network it holds (jobs dispatch on its `kind`)."""
    vma_validation_sites: tuple[Path, ...] = ()
    """Held-out site folders (rasters + ground-truth vector map) the retrain gate evaluates on."""
    vma_validation_reconstructed: tuple[Path, ...] = ()
    """Held-out synthetic sites (`cama synth`, then `cama run`) the retrain gate evaluates on the surface stage's
    reconstructed rasters, as the product proposes, against their observed truth (`models.vma.validation`)."""
    retrain_after: int = 0
    """Start a retrain job by itself after this many new accepted/fixed corrections of a site (0: never)."""
    retrain_stall_s: float = DEFAULT_RETRAIN_STALL_S
    """A retrain job whose process (with the processes below it) uses under a second of CPU for this long has hung:
    it is stopped and the job fails, saying so (`app.backend.jobs.vma.StallWatch`; 0: never stopped)."""
    qa_share: float = DEFAULT_QA_SHARE
    """Share of pre-accepted proposals sampled for the lead's QA queue."""
    preaccept_threshold: float | None = None
    """Confidence at or above which proposals enter pre-accepted; None: the registry's calibrated value."""
    review_url: str = ""
    """Where the viser 3D review (`cama view`) is served, for the editor's "3D review" link: an http(s) URL,
    or `:<port>` for that port on the host the browser reached the editor by; empty: no link."""
    review_site_id: int | None = None
    """The backend site the 3D review shows (the link carries the selected element only on that site);
    None: any site."""
    data_roots: tuple[Path, ...] = ()
    """Folders the server-side paths of requests (a site's `raster_dir` or `synthetic_dir`, an export's
    `dataset_root`) must lie in, after symlinks and `..` are resolved; empty: `data_dir` only."""
    login_max_failures: int = DEFAULT_LOGIN_MAX_FAILURES
    """Failed logins of one user name within `login_window_s` before its logins are refused (429)."""
    login_max_failures_per_address: int = DEFAULT_LOGIN_MAX_FAILURES_PER_ADDRESS
    """Failed logins from one client address within `login_window_s` before its logins are refused (429)."""
    login_window_s: float = DEFAULT_LOGIN_WINDOW_S
    """The sliding window of the login limits, seconds: a failure counts for this long."""
    max_element_vertices: int = DEFAULT_MAX_ELEMENT_VERTICES
    """Most vertices of one element; a create, bulk create or update with more gets 422 naming the limit."""
    max_site_vertices: int = DEFAULT_MAX_SITE_VERTICES
    """Most vertices of a site's live elements together; a write that would pass it gets 422 naming the limit.
    The lint's first build of a site and the memory its cache holds grow with this."""
    lint_budget_s: float = DEFAULT_LINT_BUDGET_S
    """Most seconds one request spends bringing a site's lint up to date; the elements left are linted by the
    next requests, and lint reports count them as `pending_elements` (0: one element per request)."""

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
        if self.retrain_after < 0:
            raise ValueError(f"CAMA_RETRAIN_AFTER: must be >= 0, got {self.retrain_after}")
        if not self.retrain_stall_s >= 0:
            raise ValueError(f"CAMA_RETRAIN_STALL_S: must be >= 0 seconds, got {self.retrain_stall_s}")
        if self.vma_model not in VMA_MODELS:
            raise ValueError(
                f"CAMA_VMA_MODEL: must be one of {', '.join(VMA_MODELS)}, got {self.vma_model!r}"
            )
        if not 0.0 <= self.qa_share <= 1.0:
            raise ValueError(f"CAMA_QA_SHARE: must be in [0, 1], got {self.qa_share}")
        if self.preaccept_threshold is not None and not 0.0 <= self.preaccept_threshold <= 1.0:
            raise ValueError(f"CAMA_PREACCEPT_THRESHOLD: must be in [0, 1], got {self.preaccept_threshold}")
        if self.review_url and not _REVIEW_URL.fullmatch(self.review_url):
            raise ValueError(f"CAMA_REVIEW_URL: must be an http(s) URL or :<port>, got {self.review_url!r}")
        if self.review_site_id is not None and self.review_site_id < 1:
            raise ValueError(f"CAMA_REVIEW_SITE_ID: must be a site id >= 1, got {self.review_site_id}")
        if self.login_max_failures < 1 or self.login_max_failures_per_address < 1:
            raise ValueError(
                "CAMA_LOGIN_MAX_FAILURES and CAMA_LOGIN_MAX_FAILURES_PER_ADDRESS: must be >= 1, got "
                f"{self.login_max_failures} and {self.login_max_failures_per_address}"
            )
        if not self.login_window_s > 0:
            raise ValueError(f"CAMA_LOGIN_WINDOW_S: must be positive, got {self.login_window_s}")
        if not 2 <= self.max_element_vertices <= self.max_site_vertices:
            raise ValueError(
                "CAMA_MAX_ELEMENT_VERTICES and CAMA_MAX_SITE_VERTICES: expected 2 <= per element <= per site, "
                f"got {self.max_element_vertices} and {self.max_site_vertices}"
            )
        if not self.lint_budget_s >= 0:
            raise ValueError(f"CAMA_LINT_BUDGET_S: must be >= 0, got {self.lint_budget_s}")

    @property
    def resolved_database_url(self) -> str:
        """The database URL, defaulting to a SQLite file in `data_dir`."""
        return self.database_url or f"sqlite:///{Path(self.data_dir).resolve() / 'cama.db'}"

    @property
    def allowed_data_roots(self) -> tuple[Path, ...]:
        """`data_roots` (else `data_dir`) resolved: the folders request paths may lie in."""
        return tuple(Path(root).resolve() for root in self.data_roots or (self.data_dir,))

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


_ENV_FIELDS: dict[str, Callable[[str], object]] = {
    "data_dir": Path,
    "database_url": str,
    "token_ttl_s": int,
    "max_payload_bytes": int,
    "extent_margin_m": float,
    "admin_username": str,
    "admin_password": str,
    "vma_registry": Path,
    "vma_model": str,
    "vma_validation_sites": _paths,
    "vma_validation_reconstructed": _paths,
    "retrain_after": int,
    "retrain_stall_s": float,
    "qa_share": float,
    "preaccept_threshold": float,
    "review_url": str,
    "review_site_id": int,
    "data_roots": _paths,
    "login_max_failures": int,
    "login_max_failures_per_address": int,
    "login_window_s": float,
    "max_element_vertices": int,
    "max_site_vertices": int,
    "lint_budget_s": float,
}
