"""Secrets out of the log: a filter on the log handlers that replaces every known secret (the MAVLink
signing key, API keys, the broker password) in a message or a traceback before it is written.

The code never logs a secret on purpose; this is the second line, for text that comes from outside
(a provider that quotes a rejected API key back in its error message, a library's exception).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

MIN_SECRET_LEN = 8  # shorter "secrets" would blank out ordinary words
MASK = "[redacted]"


class RedactSecrets(logging.Filter):
    def __init__(self, secrets: Iterable[str]) -> None:
        super().__init__()
        self._secrets = sorted({s for s in secrets if len(s) >= MIN_SECRET_LEN}, key=len, reverse=True)

    def redact(self, text: str) -> str:
        for s in self._secrets:
            text = text.replace(s, MASK)
        return text

    def filter(self, record: logging.LogRecord) -> bool:
        if not self._secrets:
            return True
        message = record.getMessage()
        clean = self.redact(message)
        if clean != message:
            record.msg, record.args = clean, None
        if record.exc_info and not record.exc_text:
            record.exc_text = self.redact(logging.Formatter().formatException(record.exc_info))
        return True


def redact_logs(secrets: Iterable[str], logger: logging.Logger | None = None) -> RedactSecrets:
    """Put one :class:`RedactSecrets` on every handler of ``logger`` (the root logger by default):
    a filter on a handler sees the records of every logger that propagates to it."""
    f = RedactSecrets(secrets)
    for h in (logger or logging.getLogger()).handlers:
        h.addFilter(f)
    return f
