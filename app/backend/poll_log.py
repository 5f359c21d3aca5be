"""Logs stay readable while the 3D review polls: a viewer asks for its site's element changes every 2 s, and a
line per poll (httpx's request log in the viewer, uvicorn's access log in the server) would bury everything else.

`QuietChangePolls` drops the lines of successful changes polls; failed ones are still logged. Entry points and the
viewer's backend source install it with `quiet_change_polls`.
"""

import logging

CHANGES_PATH = "/elements/changes"
"""The end of the changes route's path (`/api/sites/{site_id}/elements/changes`)."""


class QuietChangePolls(logging.Filter):
    """Drops a request log line whose arguments name the changes route and a status below 400: httpx logs
    (method, url, http version, status, reason), uvicorn's access log (client, method, path, http version,
    status)."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args if isinstance(record.args, tuple) else ()
        is_poll = any(CHANGES_PATH in str(arg) for arg in args if not isinstance(arg, int))
        statuses = [arg for arg in args if isinstance(arg, int) and not isinstance(arg, bool)]
        return not (is_poll and statuses and statuses[-1] < 400)


def quiet_change_polls(*logger_names: str) -> None:
    """Add `QuietChangePolls` to these loggers (once each)."""
    for name in logger_names:
        target = logging.getLogger(name)
        if not any(isinstance(existing, QuietChangePolls) for existing in target.filters):
            target.addFilter(QuietChangePolls())
