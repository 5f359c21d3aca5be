"""The one error type of the data-set loader, so that callers can catch bad input apart from bugs."""

from pathlib import Path


class DatasetError(ValueError):
    """A data set on disk that breaks the nuScenes layout; the message names the file, record and field."""

    def __init__(
        self,
        detail: str,
        *,
        path: Path | str | None = None,
        record: str | None = None,
        field: str | None = None,
    ) -> None:
        self.detail = detail
        """What is wrong, without the location."""
        self.path = Path(path) if path is not None else None
        """The file at fault (a table, an image, a CAN file, a folder)."""
        self.record = record
        """The record at fault: its token, or `#<index>` when it has no usable token."""
        self.field = field
        """The record's field at fault."""
        super().__init__(self._format())

    def _format(self) -> str:
        """Join location and detail into one line: `<file>: record 'tok', field 'f': <detail>`."""
        parts = []
        if self.record is not None:
            parts.append(
                f"record {self.record}" if self.record.startswith("#") else f"record {self.record!r}"
            )
        if self.field is not None:
            parts.append(f"field {self.field!r}")
        location = ", ".join(parts)
        if self.path is not None:
            location = f"{self.path}: {location}" if location else str(self.path)
        return f"{location}: {self.detail}" if location else self.detail
