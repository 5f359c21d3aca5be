"""When a stage's output is up to date: a fingerprint (a short hash of the code, config and inputs that make
it) stored with the output and compared on the next run.

Where the fingerprint is stored: outputs whose format has a `fingerprint` field carry it there (every stage's
JSON file or report), so writing the output marks it done; other outputs (the VMA proposals, an annotation set)
get a sidecar `<name>.fingerprint` holding the digest, written by `mark_done` after the output.
"""

import hashlib
import json
from pathlib import Path
from typing import Any

from cama_pipeline.io import atomic_write_bytes

SIDECAR_SUFFIX = ".fingerprint"


def fingerprint(*parts: Any) -> str:
    """A short stable hash of JSON-able parts (configs, input stats, upstream fingerprints)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def file_stats(paths: list[Path]) -> list[tuple[str, int, int]]:
    """(name, size, mtime_ns) of each existing file, for fingerprints of inputs."""
    return [(p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in paths if p.is_file()]


def sidecar(output: Path) -> Path:
    """`<output>.fingerprint`, beside the output."""
    output = Path(output)
    return output.with_name(output.name + SIDECAR_SUFFIX)


def stored_fingerprint(output: Path) -> str | None:
    """The fingerprint `output` was made with: its sidecar's when it has one, else the `fingerprint` field of the
    JSON object it holds; None when absent or unreadable."""
    stamp = sidecar(output)
    try:
        if stamp.is_file():
            return stamp.read_text(encoding="utf-8")
        value = json.loads(Path(output).read_text(encoding="utf-8")).get("fingerprint")
    except (OSError, ValueError, AttributeError):
        return None
    return value if isinstance(value, str) else None


def is_up_to_date(output: Path, digest: str) -> bool:
    """Whether `output` exists and was made with `digest` (a rerun may skip it)."""
    return Path(output).is_file() and stored_fingerprint(output) == digest


def mark_done(output: Path, digest: str) -> None:
    """Record that `output` (already written) was made with `digest`, in its sidecar; for outputs whose format
    has no `fingerprint` field."""
    atomic_write_bytes(sidecar(output), digest.encode("utf-8"))
