"""Text from outside (target names, TLE names, server messages) made safe for a terminal.

A program file, a TLE file or a client can name a target anything: a NUL, a newline that
forges a line of output, an escape sequence that recolours or clears the screen, U+202E
that turns the rest of the line around. `safe_text` writes each such character as its
Python escape (\\x00, \\n, \\x1b, \\u202e) and leaves every other character as it is.
JSON output needs none of this: json.dumps escapes them itself.
"""

from __future__ import annotations

import re

__all__ = ["safe_text"]

# C0 and C1 controls and DEL; the zero-width and bidirectional formatting characters
# (U+200B..U+200F, U+202A..U+202E, U+2066..U+2069), the line and paragraph separators,
# the word joiner and invisible operators, the BOM, and the interlinear annotations
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u200b-\u200f\u2028-\u202e\u2060-\u2069\ufeff"
                     "\ufff9-\ufffb]")


def safe_text(text: object) -> str:
    """Return `text` with control and invisible formatting characters escaped."""
    return _UNSAFE.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(text))
