"""Files named by clients and users: regular files only, size-capped, never a blocking open.

A path that a client sends (`load_model`) or a user gives (`vs run PLAN`, `vs track
--tle FILE`) is hostile until proven otherwise: a FIFO would block the reader for ever
(and, on the server's event loop, every other client with it), /dev/zero would never
end, a directory is no file. `read_text_file` opens without blocking, checks what it
opened is a regular file, and reads at most `max_bytes` of it; `read_text_file_async`
does the same in a worker thread, off the event loop.
"""

from __future__ import annotations

import asyncio
import os
import stat
from pathlib import Path

__all__ = ["FileRefused", "read_text_file", "read_text_file_async"]


class FileRefused(ValueError):
    """A file that is no regular file, too large, unreadable or not text; says which and why."""


def read_text_file(path: str | Path, *, max_bytes: int, what: str = "file") -> str:
    """Return the UTF-8 text of the regular file `path`; raise FileRefused saying why not."""
    name = str(path)
    try:
        # O_NONBLOCK: opening a FIFO without a writer would otherwise wait for ever
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise FileRefused(f"{what} {name}: {exc.strerror or exc}") from None
    except ValueError:  # a NUL in the name: no file can have it
        raise FileRefused(f"{what} {name!r}: a path cannot hold a NUL character") from None
    try:
        info = os.fstat(fd)  # what was opened, not what the name pointed at a moment before
        if not stat.S_ISREG(info.st_mode):
            raise FileRefused(f"{what} {name}: {_kind(info.st_mode)}, not a regular file")
        if info.st_size > max_bytes:
            raise FileRefused(f"{what} {name}: {info.st_size} bytes, more than the "
                              f"{max_bytes} allowed")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=True) as f:
            fd = -1
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise FileRefused(f"{what} {name}: {exc.strerror or exc}") from None
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > max_bytes:  # it grew while being read
        raise FileRefused(f"{what} {name}: more than the {max_bytes} bytes allowed")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileRefused(f"{what} {name}: not UTF-8 text (byte {exc.start})") from None


async def read_text_file_async(path: str | Path, *, max_bytes: int, what: str = "file") -> str:
    """`read_text_file` in a worker thread: the event loop serves others meanwhile."""
    return await asyncio.to_thread(read_text_file, path, max_bytes=max_bytes, what=what)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a special file"
