"""The VSS side of the mount connection: one ASTCom client, one request at a time.

The mount's controller processes requests synchronously while the VSS is fully
asynchronous, so every request goes through one asyncio.Lock: feeder pushes,
status reads and operator commands queue up and are never interleaved. The
link reconnects by itself with exponential backoff and reports
``mount_connected`` / ``mount_disconnected`` / ``mount_connect_failed`` events.
Roles are translated to mount names by a `RoleMapping`; signal values come back
in VSS units (radians for angles, arcseconds for errors) whatever the mount's
own unit, which is learnt from the mount's listing.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any

from astcom_client import AstcomError, Client, ConnectionClosed, DeviceError, Stream
from virtualstar.astro.constants import ARCSEC_PER_RAD

from .exceptions import MappingError, MountRejected, MountUnavailable
from .link_interface import ConnectionWaits, MountCapabilities
from .mapping import RoleMapping
from .operations import current_operation

__all__ = ["LinkConfig", "MountCall", "MountLink"]

log = logging.getLogger("virtualstar.server.mount")

_ERROR_ROLES = ("az_error", "el_error")
CALL_LOG = 4096  # function calls kept in `MountLink.calls`


@dataclass(frozen=True)
class MountCall:
    """One function the VSS called on the mount: order, role, and the operation that sent it."""

    seq: int
    role: str
    operation: int | None  # None: outside any operation (stop, TimeS, a reconnection)


@dataclass(frozen=True)
class LinkConfig:
    """Where the mount is and how patiently to reach it (wall seconds).

    `connector`, when given, opens the connection instead of dialling `url` (the
    embedded emulator in lockstep: an in-memory ASTCom client); `url` then only
    names it in messages.
    """

    url: str
    password: str | None = None
    timeout_s: float = 5.0
    backoff_min_s: float = 0.2
    backoff_max_s: float = 5.0
    poll_s: float = 0.05  # how often a silent loss of the connection is looked for
    connector: Callable[[], Awaitable[Client]] | None = None


class MountLink(ConnectionWaits):
    """A self-healing, serialised ASTCom connection to a mount, spoken in roles.

    The ASTCom backend of the mount-link interface (`link_interface.MountBackend`): the
    controller follows timed points from its trajectory buffer and streams its own
    following error, so the VSS never closes a loop over the network.
    """

    def __init__(self, config: LinkConfig, mapping: RoleMapping, *,
                 on_event: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.config = config
        self.mapping = mapping
        self.on_event = on_event or (lambda kind, data: None)
        self._lock = asyncio.Lock()
        self._client: Client | None = None
        self._connected = asyncio.Event()
        self._changed = asyncio.Condition()
        self._lost = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._stopping = False  # stop() was called: the manager ends, cancelled or not
        self._scale: dict[str, float] = {}
        self._call_seq = itertools.count(1)
        self.calls: deque[MountCall] = deque(maxlen=CALL_LOG)
        self.connects = 0
        self.last_error = ""

    # ------------------------------------------------------------------ lifecycle
    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    @property
    def capabilities(self) -> MountCapabilities:
        """An ASTCom controller as the mapping describes it: an alt-az mount with a buffer."""
        m = self.mapping
        return MountCapabilities(backend="astcom", geometry="altaz", trajectory_buffer=True,
                                 goto=True, park=True, guide=True,
                                 time_sync=m.has_function("time_sync"), error_stream=True)

    def describe(self) -> dict[str, Any]:
        """The backend's part of the status (the error itself comes from the mount's stream)."""
        return {"backend": "astcom", "url": self.config.url,
                "capabilities": self.capabilities.as_dict()}

    def start(self) -> None:
        """Start connecting (and reconnecting) in the background."""
        if self._task is None:
            self._stopping = False
            self._task = asyncio.get_running_loop().create_task(self._manage(), name="mount-link")

    async def stop(self) -> None:
        """Stop reconnecting and close the connection."""
        self._stopping = True
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self._client is not None:
            with contextlib.suppress(Exception):
                await self._client.close()
            self._client = None
        self._connected.clear()

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    def mark_lost(self) -> None:
        """Declare the connection broken (a request failed); the manager reconnects."""
        self._lost.set()

    async def _manage(self) -> None:
        delay = self.config.backoff_min_s
        # `_stopping` as well as the cancellation: a cancellation swallowed below us (Python
        # 3.11's wait_for returns a result that was ready instead of raising it) must not
        # leave this loop reconnecting forever while stop() waits for it
        while not self._stopping:
            try:
                client = await self._open()
            except (OSError, AstcomError, TimeoutError) as exc:
                self._failed(str(exc) or type(exc).__name__)
                await asyncio.sleep(delay)
                delay = min(2 * delay, self.config.backoff_max_s)
                continue
            try:
                await self._learn_units(client)
            except MappingError as exc:
                await client.close()
                self._failed(str(exc))
                await asyncio.sleep(self.config.backoff_max_s)
                continue
            except (OSError, AstcomError, TimeoutError) as exc:
                await client.close()
                self._failed(str(exc))
                await asyncio.sleep(delay)
                continue
            delay = self.config.backoff_min_s
            self._lost.clear()
            self._client = client
            self.connects += 1
            self._connected.set()
            await self._notify()
            log.info("mount connected at %s", self.config.url)
            self.on_event("mount_connected", {"url": self.config.url, "connects": self.connects})
            while client.connected and not self._lost.is_set() and not self._stopping:
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(self.config.poll_s):
                        await self._lost.wait()
            self._connected.clear()
            self._client = None
            await self._notify()
            with contextlib.suppress(Exception):
                await client.close()
            if self._stopping:
                return
            self.last_error = "connection lost"
            log.warning("mount connection lost")
            self.on_event("mount_disconnected", {"url": self.config.url})

    async def _open(self) -> Client:
        if self.config.connector is not None:
            return await self.config.connector()
        return await Client.connect(self.config.url, password=self.config.password,
                                    name="virtualstar-server", timeout_s=self.config.timeout_s)

    def _failed(self, reason: str) -> None:
        if reason != self.last_error:
            log.warning("cannot connect to the mount at %s: %s", self.config.url, reason)
            self.on_event("mount_connect_failed", {"url": self.config.url, "reason": reason})
        self.last_error = reason

    async def _learn_units(self, client: Client) -> None:
        entries = {e.name: e for e in await client.list()}
        wanted = list(self.mapping.signals.items()) + list(self.mapping.functions.items())
        missing = [f"{role} -> {name}" for role, name in wanted if name not in entries]
        if missing:
            raise MappingError(f"{self.mapping.source}: the mount at {self.config.url} has no "
                               f"{'; '.join(missing)}")
        scale = {}
        for role, name in self.mapping.signals.items():
            unit = entries[name].unit.strip().lower()
            if role in _ERROR_ROLES:
                scale[role] = ARCSEC_PER_RAD if unit == "rad" else 1.0
            else:
                scale[role] = math.pi / 180.0 if unit.startswith("deg") else 1.0
        self._scale = scale

    # ------------------------------------------------------------------ requests
    def _require(self) -> Client:
        client = self._client
        if client is None or not client.connected:
            raise MountUnavailable(f"the mount at {self.config.url} is not connected "
                                   f"({self.last_error or 'connecting'}); the server keeps retrying")
        return client

    async def _do(self, what: str, request: Callable[[Client], Any]) -> Any:
        async with self._lock:
            client = self._require()
            try:
                return await request(client)
            except DeviceError as exc:
                raise MountRejected(f"the mount refused {what}: {exc.message or exc}") from None
            except (ConnectionClosed, ConnectionError, TimeoutError) as exc:
                self.mark_lost()
                raise MountUnavailable(f"lost the mount during {what}: {exc}") from None
            except AstcomError as exc:
                raise MountRejected(f"the mount refused {what}: {exc}") from None

    async def read(self, roles: Sequence[str]) -> dict[str, Any]:
        """Return {role: value} of signal roles at one tick, in VSS units."""
        names = [self.mapping.signal(r) for r in roles]
        values = await self._do(f"reading {', '.join(names)}", lambda c: c.read(names))
        out = {}
        for role, name in zip(roles, names, strict=True):
            v = values[name]
            s = self._scale.get(role, 1.0)
            out[role] = v * s if s != 1.0 and isinstance(v, int | float) else v
        return out

    async def call(self, role: str, *args: Any) -> Any:
        """Invoke the mount function playing `role` with `args`; return its value."""
        name = self.mapping.function(role)
        self.calls.append(MountCall(next(self._call_seq), role, current_operation.get()))
        return await self._do(f"{name}()", lambda c: c.invoke(name, *args))

    async def write_raw(self, values: dict[str, Any]) -> None:
        """Write mount variables by their own names (operator tools and tests)."""
        await self._do("a write", lambda c: c.write(values))

    async def stream(self, roles: Sequence[str], rate_hz: float) -> Stream:
        """Start a stream of signal roles; values arrive in the mount's own units."""
        names = [self.mapping.signal(r) for r in roles]
        return await self._do(f"streaming {', '.join(names)}", lambda c: c.stream(names, rate_hz))

    def scale(self, role: str) -> float:
        """Return the factor from the mount's unit of `role` to VSS units."""
        return self._scale.get(role, 1.0)
