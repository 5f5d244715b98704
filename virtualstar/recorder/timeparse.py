"""Parse the time bounds of a query: ISO-8601 UTC, mount µs, or seconds from the ends."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from .exceptions import QueryError

__all__ = ["parse_time_bound", "utc_text"]

_FORMS = ("expected 'start', 'end', +SECONDS (after the first sample), -SECONDS (before the "
          "last), an ISO-8601 UTC time such as 2026-03-01T20:00:00Z, or mount time in integer µs")


def parse_time_bound(text: str, start_us: int, end_us: int, *, option: str = "--from") -> int:
    """Return the mount time (µs) that `text` names, given the store's first and last sample.

    "end" means just after the last sample, so ``--to end`` includes it.
    Raises QueryError naming the accepted forms.
    """
    s = text.strip()
    low = s.lower()
    if low == "start":
        return start_us
    if low == "end":
        return end_us + 1
    try:
        if len(s) > 1 and s[0] in "+-":
            seconds = float(s[1:])
            if not math.isfinite(seconds) or seconds < 0:
                raise ValueError
            offset = round(seconds * 1e6)
            return start_us + offset if s[0] == "+" else end_us + 1 - offset
        if s.isdigit():
            return int(s)
    except ValueError:
        raise QueryError(f"{option} {text!r}: {_FORMS}") from None
    try:
        when = datetime.fromisoformat(s.replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise QueryError(f"{option} {text!r}: {_FORMS}") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000 + delta.microseconds


def utc_text(t_us: int) -> str:
    """Return mount time `t_us` as ISO-8601 UTC text with microseconds."""
    return datetime.fromtimestamp(t_us / 1e6, UTC).isoformat(timespec="microseconds").replace(
        "+00:00", "Z")
