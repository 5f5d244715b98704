"""What `vs track --wait` shows while it waits: the pass ahead and how long until it starts.

The server tells its clients each phase of the operation (pass planned, slewing, waiting,
joining, tracking...) with the pass's times; the mount clock is read from `status` once a
second, so the countdown is in mount time (right at --speed max as at real time). At a
terminal one line is redrawn in place; into a pipe or a file, a line per phase and one a
minute while waiting.
"""

from __future__ import annotations

import asyncio
import threading
import time
from datetime import UTC, datetime
from typing import Any, TextIO

__all__ = ["WaitDisplay", "wait_text"]

#: Into a pipe, a progress line at most this often (wall seconds) within one phase.
PIPED_LINE_EVERY_S = 60.0
#: The mount clock is read this often (wall seconds).
POLL_S = 1.0


#: Phases before the pass (a countdown to its start) and during it (the time left).
_BEFORE = frozenset({"starting", "preparing", "pass planned", "slewing", "waiting"})
_DURING = frozenset({"joining", "settling", "tracking", "interrupted"})


def _us(text: str | None) -> int | None:
    if not text:
        return None
    when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return round(when.timestamp() * 1e6)


def _span(seconds: float) -> str:
    s = max(0, int(round(seconds)))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h} h {m:02d} min {s:02d} s" if h else (f"{m} min {s:02d} s" if m else f"{s} s")


def wait_text(op: dict[str, Any], mount_us: int | None) -> str:
    """Return one line about an operation: its phase, the pass, the time until it starts
    or ends (mount time, when `mount_us` is known)."""
    from virtualstar.display import safe_text

    info = op.get("info", {})
    phase = op.get("phase", "?")
    if mount_us is None and phase == "pass planned":
        mount_us = info.get("slew_from_us")  # the mount time the pass was planned at
    head = f"{safe_text(op.get('kind', ''))} {safe_text(op.get('target', ''))}: {phase}"
    start_us, end_us = _us(info.get("pass_start_utc")), _us(info.get("pass_end_utc"))
    parts = []
    if mount_us is not None and phase in _BEFORE:
        begin = start_us if start_us is not None else _us(info.get("start_utc"))
        if begin is not None and mount_us < begin:
            what = "the pass starts" if start_us is not None else "starts"
            parts.append(f"{what} in {_span((begin - mount_us) / 1e6)}")
    elif mount_us is not None and phase in _DURING and end_us is not None and mount_us < end_us:
        parts.append(f"{_span((end_us - mount_us) / 1e6)} of the pass left")
    if info.get("pass_start_utc"):
        rise = info.get("pass_rise_utc")
        culm = info.get("culmination_el_deg")
        parts.append(("rise " + rise[11:19] + ", " if rise else "")
                     + f"tracked {info['pass_start_utc'][11:19]}–"
                     f"{(info.get('pass_end_utc') or '?')[11:19]} UTC"
                     + (f", culmination {culm:.1f}°" if culm is not None else ""))
    if mount_us is not None:
        parts.append(f"mount time {datetime.fromtimestamp(mount_us / 1e6, UTC):%H:%M:%S}")
    return head + (" — " + "; ".join(parts) if parts else "")


class WaitDisplay:
    """Show an operation's progress until `close()`; feed it the server's events."""

    def __init__(self, url: str, *, password: str | None, terminal: bool, out: TextIO,
                 console=None) -> None:
        self.url = url
        self.password = password
        self.terminal = terminal
        self.out = out
        self.console = console
        self.op: dict[str, Any] | None = None
        self._read: tuple[int, float] | None = None  # last (mount µs, wall monotonic s) read
        self._rate = 1.0  # mount seconds per wall second, from the last two readings
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._status = None
        self._last_phase: str | None = None
        self._last_line_s = 0.0
        self._thread = threading.Thread(target=self._poll, name="vs-wait", daemon=True)

    def __enter__(self) -> WaitDisplay:
        if self.terminal and self.console is not None:
            self._status = self.console.status("waiting for the server...")
            self._status.__enter__()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5)
        if self._status is not None:
            self._status.__exit__(None, None, None)
            self._status = None

    def on_event(self, kind: str, data: dict[str, Any]) -> None:
        """An event of the server (the connection awaiting the command's answer)."""
        if kind == "operation":
            with self._lock:
                self.op = data
            self._show(phase_changed=data.get("phase") != self._last_phase)
        elif kind == "fault":
            self._line(f"mount fault: {data.get('faults')}")

    def _poll(self) -> None:
        """Read the mount clock from `status` (a connection of its own) once a second."""
        asyncio.run(self._poll_status())

    async def _poll_status(self) -> None:
        from virtualstar.vss_client import ServerUnavailable, VssClient, VssRequestError

        try:
            client = await VssClient.connect(self.url, password=self.password)
        except (ServerUnavailable, OSError):
            return  # no countdown, the phases still show
        async with client:
            while not self._stop.is_set():
                try:
                    st = await client.request("status", {}, 10.0)
                except (TimeoutError, VssRequestError, ServerUnavailable, OSError):
                    return
                if st.get("mount_time_us") is not None:
                    self._note(int(st["mount_time_us"]), time.monotonic())
                    self._show(phase_changed=False)
                await asyncio.get_running_loop().run_in_executor(None, self._stop.wait, POLL_S)

    def _note(self, mount_us: int, wall_s: float) -> None:
        with self._lock:
            if self._read is not None and wall_s > self._read[1]:
                self._rate = max(0.0, (mount_us - self._read[0]) / 1e6 / (wall_s - self._read[1]))
            self._read = (mount_us, wall_s)

    @property
    def mount_us(self) -> int | None:
        """The mount time now, from the last reading and the clock's rate since (µs)."""
        if self._read is None:
            return None
        mount_us, wall_s = self._read
        return mount_us + int(self._rate * (time.monotonic() - wall_s) * 1e6)

    def _show(self, *, phase_changed: bool) -> None:
        with self._lock:
            if self.op is None:
                return
            text = wait_text(self.op, self.mount_us)
            phase = self.op.get("phase")
        if self.terminal:
            if self._status is not None:
                from rich.markup import escape

                self._status.update(escape(text))
            return
        now = time.monotonic()
        if phase_changed or (phase == "waiting" and now - self._last_line_s >= PIPED_LINE_EVERY_S):
            self._last_phase = phase
            self._last_line_s = now
            self._line(text)

    def _line(self, text: str) -> None:
        if self.terminal and self.console is not None:
            self.console.print(text, markup=False, highlight=False)
        else:
            print(text, file=self.out, flush=True)
