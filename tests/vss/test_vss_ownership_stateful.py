"""A stateful property test: 2–4 clients fire random commands at the real VSS and emulator.

Hypothesis interleaves commands (slew, track, satellite pass, park, stop) from
several in-process clients with stretches of mount time, in lockstep: the clock
is frozen between steps, so each step runs until nothing can run, and the same
program gives the same run. After every step it checks what an operator relies on:

* at most one operation drives the mount: every function the VSS calls on the mount
  is logged with the operation that sent it, and once an operation has sent one,
  no older operation sends another; one operation task, one feeder at a time;
* once a `stop` is answered, and until a newer command is sent, nothing is sent to
  the mount that moves it and the mount holds still (state HOLDING or OFF,
  encoders unchanged);
* the status agrees with the mount (state and encoders, read at the same instant
  from the emulator by a connection of the test's own);
* at the end every request has been answered, exactly once.
"""

from __future__ import annotations

import asyncio
import math
from concurrent.futures import Future

import pytest
from hypothesis import HealthCheck, event, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule
from vss_rig import Rig

from catalogs import load_tle_file, sample_tle_path
from virtualstar.astro import UtcTimes, load_site
from virtualstar.server.local_client import LocalVssClient
from virtualstar.server.supervisor import operations_of_tasks
from virtualstar.vss_client import VssRequestError

START = "2024-05-18T19:40:00Z"  # Vega, Arcturus, Deneb up; an ISS pass at 19:51
STILL_RAD = math.radians(10 / 3600)  # a holding mount settles by ~1″ after a stopped slew, no more
MOVING = ("slew", "track", "park")
MOTION_ROLES = {"power_on", "power_off", "stop", "slew", "traj_init", "traj_start", "traj_reset",
                "traj_push", "reset_faults"}
AT_REST_ROLES = {"stop", "traj_reset"}  # what a stop itself may send (no operation)

_RIG: Rig | None = None


def shared_rig() -> Rig:
    """One emulator + VSS for every example (lockstep, unpaced, clock frozen between steps)."""
    global _RIG
    if _RIG is None:
        start_us = int(UtcTimes.from_iso([START]).to_unix_us()[0])
        _RIG = Rig(start_us=start_us, site=load_site(), pace=None).start(listen=None)
        _RIG.clock.freeze()
    return _RIG


@pytest.fixture(scope="module", autouse=True)
def _close_rig():
    yield
    global _RIG
    if _RIG is not None:
        _RIG.close()
        _RIG = None


def commands():
    star = st.sampled_from(["Vega", "Arcturus", "Deneb"])
    altaz = st.tuples(st.integers(0, 359), st.integers(10, 85)).map(lambda a: f"{a[0]} {a[1]}")
    rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    tle = f"{rec.name}\n{rec.line1}\n{rec.line2}\n"
    return st.one_of(
        st.builds(lambda s: ("slew", {"star": s}), star),
        st.builds(lambda a: ("slew", {"altaz": a}), altaz),
        st.builds(lambda s, d, w: ("track", {"star": s, "duration_s": d, "wait": w}),
                  star, st.sampled_from([2.0, 10.0, 30.0]), st.booleans()),
        st.just(("track", {"tle": tle, "sat": "ISS"})),
        st.builds(lambda w: ("park", {"wait": w}), st.booleans()),
        st.just(("stop", {})),
    )


class OneOwnerOfTheMount(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.rig = shared_rig()
        self.server = self.rig.server
        self.requests: list[tuple[int, str, Future]] = []
        self.seq = 0
        self.last_move_seq = -1  # seq of the newest command that may move the mount
        self.stops: list[tuple[int, Future]] = []
        self.still_at: dict[str, float] | None = None  # encoders when a stop was answered
        self.still_after_call = 0  # ... and the last mount call then
        self.still_after_op = 0  # ... and the newest operation then
        self.newest_op_seen = 0
        self.calls_checked = 0

    @initialize(n_clients=st.integers(2, 4))
    def connect(self, n_clients: int) -> None:
        self.clients = [LocalVssClient(self.server) for _ in range(n_clients)]
        self._settle()

    # ------------------------------------------------------------------ steps
    @rule(data=st.data(), command=commands())
    def send(self, data, command) -> None:
        self._fire(data.draw(st.integers(0, len(self.clients) - 1)), command)
        self._settle()

    @rule(data=st.data(), burst=st.lists(commands(), min_size=2, max_size=4))
    def send_at_once(self, data, burst) -> None:
        """Several clients at the same instant: each request meets the others half-way."""
        for command in burst:
            self._fire(data.draw(st.integers(0, len(self.clients) - 1)), command)
        self._settle()

    def _fire(self, client: int, command) -> None:
        cmd, params = command
        self.seq += 1
        fut = asyncio.run_coroutine_threadsafe(self.clients[client].request(cmd, params),
                                               self.rig.loop)
        self.requests.append((self.seq, cmd, fut))
        if cmd in MOVING:
            self.last_move_seq = self.seq
            self.still_at = None
        else:
            self.stops.append((self.seq, fut))

    @rule(mount_s=st.sampled_from([0.1, 1.0, 5.0, 20.0, 60.0]))
    def let_time_pass(self, mount_s: float) -> None:
        self.rig.run(self.rig.clock.advance(mount_s), 300.0)
        self._settle()

    def send_stop(self) -> None:
        self.seq += 1
        fut = asyncio.run_coroutine_threadsafe(self.clients[0].request("stop"), self.rig.loop)
        self.requests.append((self.seq, "stop", fut))
        self.stops.append((self.seq, fut))
        self._settle()

    def _settle(self) -> None:
        self.rig.run(self.rig.clock.settled(), 300.0)
        # a stop answered after the newest moving command: from now on the mount holds still
        for seq, fut in self.stops:
            if fut.done() and seq > self.last_move_seq and self.still_at is None \
                    and fut.exception() is None:
                self.still_at = self._mount()[0]
                calls = list(self.server.telescope.link.calls)
                self.still_after_call = calls[-1].seq if calls else 0
                self.still_after_op = self.server.telescope.supervisor.operations_started
        self.stops = [(s, f) for s, f in self.stops if not f.done()]

    def _mount(self) -> tuple[dict, dict]:
        async def read():
            observer = await self.rig.emulator.connect_in_memory(name="test-observer")
            try:
                values, _, t_us = await observer.read_at(
                    ["axis.az.position", "axis.el.position", "mount.state_name"])
                status = await self.server.call("status")
            finally:
                await observer.close()
            return values, status

        return self.rig.run(read())

    # ------------------------------------------------------------------ invariants
    @invariant()
    def no_older_operation_commands_the_mount_after_a_newer_one(self) -> None:
        calls = [c for c in self.server.telescope.link.calls
                 if c.seq > self.calls_checked and c.role in MOTION_ROLES]
        for call in calls:
            if call.operation is not None:
                assert call.operation >= self.newest_op_seen, (call, self.newest_op_seen)
                self.newest_op_seen = call.operation
            if self.still_at is not None and call.seq > self.still_after_call:
                # after an answered stop: only newer operations, or another stop bringing to rest
                assert (call.operation or 0) > self.still_after_op or (
                    call.operation is None and call.role in AT_REST_ROLES), call
        if calls:
            self.calls_checked = calls[-1].seq

    @invariant()
    def one_operation_drives_the_mount(self) -> None:
        async def live():
            names = [t.get_name() for t in asyncio.all_tasks() if not t.done()]
            ops = operations_of_tasks(names)
            return ops, names.count("vss-feeder")

        ops, feeders = self.rig.run(live())
        assert len(ops) <= 1, ops
        assert feeders <= len(ops), (ops, feeders)

    @invariant()
    def the_status_agrees_with_the_mount_and_a_stop_holds(self) -> None:
        values, status = self._mount()
        assert status["mount_state"].upper() == values["mount.state_name"]
        for axis in ("az", "el"):
            assert status["encoder"][f"{axis}_deg"] == pytest.approx(
                math.degrees(values[f"axis.{axis}.position"]), abs=1e-9)
        if self.still_at is not None:
            assert values["mount.state_name"] in ("HOLDING", "OFF"), status["operation"]
            for name in ("axis.az.position", "axis.el.position"):
                assert abs(values[name] - self.still_at[name]) < STILL_RAD

    def teardown(self) -> None:
        if not hasattr(self, "clients"):
            return
        self.send_stop()
        self.rig.run(self.rig.clock.advance(5.0), 300.0)
        self._settle()
        unanswered = [(seq, cmd) for seq, cmd, fut in self.requests if not fut.done()]
        assert not unanswered, unanswered
        for _seq, cmd, fut in self.requests:  # answered: a result, or the API's error
            exc = fut.exception()
            event(f"{cmd}: {exc.code if exc is not None else 'ok'}")
            assert exc is None or isinstance(exc, VssRequestError), repr(exc)
            if isinstance(exc, VssRequestError):
                assert exc.code != "internal", exc
        for client in self.clients:
            self.rig.run(client.close())


OneOwnerOfTheMount.TestCase.settings = settings(
    max_examples=15, stateful_step_count=30, deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
test_random_commands_from_several_clients_keep_one_owner_of_the_mount = OneOwnerOfTheMount.TestCase
