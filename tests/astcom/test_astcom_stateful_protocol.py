"""Random command sequences against the endpoint core keep the protocol's invariants.

A hypothesis state machine plays a client that may misbehave (wrong order, wrong
password, unknown names, garbage) against the sans-I/O server core and the endpoint
service, publishing device ticks in between, and checks after every step:
no stream packet for a message that is not streamed, nothing readable before
authentication, one reply per request, no gap in any stream, register = model.
"""

import os

from hypothesis import event, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from astcom_client import AstcomError
from astcom_client.auth import Authenticator, client_mac
from astcom_client.codec import Codec
from astcom_client.example_device import ExampleDevice
from astcom_client.protocol import RequestReceived, ServerConnection, ServerOptions, ServerState
from astcom_client.service import EndpointService, PendingInvoke, ServiceLimits

PASSWORDS = {"operator": "op", "observer": "obs"}
STREAMABLE = ["counter", "wave.sine", "gains", "wave.amplitude", "power.limits.enabled"]
NAMES = [*STREAMABLE, "label", "no.such.name"]
READABLE_KEYS = {"values", "entries", "msg", "value", "clients"}


class ProtocolMachine(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.device = ExampleDevice(loop_rate_hz=1000.0, start_t_us=0)
        self.codec = Codec()
        self.service = EndpointService(self.device.collection, self.codec, loop_rate_hz=1000.0,
                                       limits=ServiceLimits(flush_interval_s=0.005))
        options = ServerOptions(Authenticator(PASSWORDS), self.codec, queue_packets=100_000)
        self.conn = ServerConnection(options, client_id=1)
        self.service.attach(self.conn)
        self.seq = 0
        self.nonce = b""
        self.authed = False
        self.role = ""
        self.defined: dict[int, tuple[str, ...]] = {}
        self.streaming: dict[int, int] = {}  # msg -> k
        self.next_tick: dict[int, int] = {}
        self.next_seq: dict[int, int] = {}

    # -- plumbing ----------------------------------------------------------------------------
    def request(self, op: str, args: dict) -> list:
        self.seq += 1
        return self.exchange(self.codec.encode([op, self.seq, args]), self.seq)

    def exchange(self, data: bytes, seq: int | None) -> list:
        for happened in self.conn.receive_frame(data):
            if isinstance(happened, RequestReceived):
                try:
                    result = self.service.execute(self.conn, happened.command)
                except AstcomError as exc:  # exactly what the Endpoint does; others fail
                    self.conn.send_error(happened.seq, exc)
                    continue
                if isinstance(result, PendingInvoke):
                    result.awaitable.close()
                    result = {"value": None}
                self.conn.send_result(happened.seq, result)
        frames = self.drain()
        replies = [f for f in frames if f[0] != "DATA"]
        if seq is not None and self.conn.close_code not in (408,):
            assert [r[1] for r in replies if r[1] is not None] in ([seq], [])
            assert len([r for r in replies if r[1] == seq]) == 1
        if self.conn.state is ServerState.CLOSED:
            self.service.detach(self.conn)
            self.defined.clear()
            self.streaming.clear()
        return replies

    def drain(self) -> list:
        frames = []
        while (frame := self.conn.next_frame()) is not None:
            frames.append(self.codec.decode(frame))
        for frame in frames:
            if frame[0] == "DATA":
                self.check_packet(frame)
            elif frame[0] == "OK" and not self.authed:
                assert not READABLE_KEYS & set(frame[2]), f"readable before AUTH: {frame}"
        return frames

    def check_packet(self, frame: list) -> None:
        _, msg, seq, first_tick, _, _, k, n, arrays = frame
        event("stream packet checked")
        assert msg in self.streaming, f"packet for message {msg} that is not streamed"
        assert k == self.streaming[msg] and first_tick % k == 0
        if msg in self.next_tick:
            assert first_tick == self.next_tick[msg] and seq == self.next_seq[msg]
        self.next_tick[msg] = first_tick + n * k
        self.next_seq[msg] = seq + 1
        assert all(a.shape[0] == n for a in arrays)

    def reply(self, op: str, args: dict) -> list:
        replies = self.request(op, args)
        return replies[0] if replies else None

    # -- rules ----------------------------------------------------------------------------
    open_ = precondition(lambda self: self.conn.state is not ServerState.CLOSED)

    @initialize(password=st.sampled_from(["op", "obs", None, None]))
    def start(self, password: str | None) -> None:
        """Begin after HELLO, authenticated as operator or observer, or not at all."""
        self.hello()
        if password is not None:
            self.auth(password)

    @open_
    @rule()
    def hello(self) -> None:
        first = self.conn.state is ServerState.AWAIT_HELLO
        r = self.reply("HELLO", {"version": "1.0"})
        if first:
            assert r[0] == "OK"
            self.nonce = r[2]["nonce"]
        else:
            assert r[0] == "ERR" and r[2]["code"] == 409

    @open_
    @rule(password=st.sampled_from(["op", "obs", "wrong"]))
    def auth(self, password: str) -> None:
        state = self.conn.state
        cnonce = os.urandom(16)
        r = self.reply("AUTH", {"cnonce": cnonce, "mac": client_mac(password, self.nonce, cnonce)})
        if state is ServerState.AWAIT_AUTH and password != "wrong":
            assert r[0] == "OK" and r[2]["role"] == ("operator" if password == "op" else "observer")
            self.authed, self.role = True, r[2]["role"]
            event("authenticated")
        else:
            assert r[0] == "ERR" and r[2]["code"] in (401, 409)
            if not self.authed:
                assert self.conn.state is ServerState.CLOSED

    @open_
    @rule(names=st.lists(st.sampled_from(STREAMABLE), min_size=1, max_size=3, unique=True))
    def define(self, names: list[str]) -> None:
        self.define_any(names)

    @open_
    @rule(names=st.lists(st.sampled_from(NAMES), min_size=1, max_size=4, unique=True))
    def define_any(self, names: list[str]) -> None:
        r = self.reply("DEFINE", {"names": names})
        if not self.authed:
            assert r[0] == "ERR" and r[2]["code"] == 409
        elif "no.such.name" in names:
            assert r[0] == "ERR" and r[2]["code"] == 404
        else:
            assert r[0] == "OK"
            self.defined[r[2]["msg"]] = tuple(names)

    def pick(self, data: st.DataObject) -> int:
        return data.draw(st.sampled_from([*self.defined, 999]))

    @open_
    @rule(data=st.data())
    def read(self, data: st.DataObject) -> None:
        msg = self.pick(data)
        r = self.reply("READ", {"msg": msg})
        if self.authed and msg in self.defined:
            assert r[0] == "OK" and len(r[2]["values"]) == len(self.defined[msg])
        else:
            assert r[0] == "ERR"

    @open_
    @rule(data=st.data(), value=st.floats(-10, 10))
    def write(self, data: st.DataObject, value: float) -> None:
        names = data.draw(st.sampled_from([("wave.amplitude",), ("wave.amplitude", "counter")]))
        if not self.authed:
            return
        r = self.reply("DEFINE", {"names": list(names)})
        self.defined[r[2]["msg"]] = names
        before = self.device.params[0]
        r = self.reply("WRITE", {"msg": r[2]["msg"], "values": [value] * len(names)})
        if self.role == "observer":
            assert r[2]["code"] == 403
        elif "counter" in names:
            assert r[2]["code"] == 405
        elif value < 0.0:  # wave.amplitude declares the range 0..100 V: nothing applied
            assert r[2]["code"] == 422 and self.device.params[0] == before
        else:
            assert r[0] == "OK" and self.device.params[0] == value

    @open_
    @precondition(lambda self: self.defined)
    @rule(data=st.data(), rate_hz=st.sampled_from([100.0, 250.0, 1000.0]))
    def stream_start(self, data: st.DataObject, rate_hz: float) -> None:
        self.stream_start_any(data.draw(st.sampled_from(list(self.defined))), rate_hz)

    @open_
    @rule(names=st.lists(st.sampled_from(STREAMABLE), min_size=1, max_size=3, unique=True),
          rate_hz=st.sampled_from([100.0, 250.0, 1000.0]), n_ticks=st.integers(1, 60))
    def define_stream_and_publish(self, names: list[str], rate_hz: float, n_ticks: int) -> None:
        self.define_any(names)
        if self.authed:
            self.stream_start_any(max(self.defined), rate_hz)
        self.publish(n_ticks)

    @open_
    @rule(data=st.data(), rate_hz=st.sampled_from([1.0, 100.0, 250.0, 1000.0, 5000.0]))
    def stream_start_random(self, data: st.DataObject, rate_hz: float) -> None:
        self.stream_start_any(self.pick(data), rate_hz)

    def stream_start_any(self, msg: int, rate_hz: float) -> None:
        r = self.reply("STREAM_START", {"msg": msg, "rate_hz": rate_hz})
        ok = (self.authed and msg in self.defined and rate_hz <= 1000.0
              and "label" not in self.defined[msg])
        assert (r[0] == "OK") == ok, r
        if ok:
            k = r[2]["period_ticks"]
            if self.streaming.get(msg) != k:
                self.next_tick.pop(msg, None)
                self.next_seq.pop(msg, None)
            self.streaming[msg] = k

    @open_
    @rule(data=st.data())
    def stream_stop(self, data: st.DataObject) -> None:
        msg = data.draw(st.sampled_from([*self.streaming, 999]))
        r = self.reply("STREAM_STOP", {"msg": msg})
        assert (r[0] == "OK") == (self.authed and msg in self.streaming)
        self.streaming.pop(msg, None)
        self.next_tick.pop(msg, None)
        self.next_seq.pop(msg, None)

    @open_
    @precondition(lambda self: self.streaming)
    @rule(data=st.data())
    def undefine_a_streamed_message(self, data: st.DataObject) -> None:
        self.undefine_msg(data.draw(st.sampled_from(list(self.streaming))))

    @open_
    @rule(data=st.data())
    def undefine(self, data: st.DataObject) -> None:
        self.undefine_msg(self.pick(data))

    def undefine_msg(self, msg: int) -> None:
        r = self.reply("UNDEFINE", {"msg": msg})
        assert (r[0] == "OK") == (self.authed and msg in self.defined)
        self.defined.pop(msg, None)
        self.streaming.pop(msg, None)
        self.next_tick.pop(msg, None)
        self.next_seq.pop(msg, None)

    @rule(n_ticks=st.integers(1, 60))
    def publish(self, n_ticks: int) -> None:
        first = self.device.tick
        trace = self.device.step(n_ticks)
        self.service.publish(first, self.device.t_us_of(first), n_ticks, trace)
        self.drain()

    @open_
    @rule(data=st.binary(max_size=40))
    def garbage(self, data: bytes) -> None:
        self.exchange(data, None)

    @open_
    @rule()
    def bye(self) -> None:
        r = self.reply("BYE", {})
        assert r[0] == "OK" and self.conn.state is ServerState.CLOSED

    # -- invariants ---------------------------------------------------------------------------
    @invariant()
    def register_matches_the_model(self) -> None:
        assert set(self.service.messages) == set(self.defined)
        streams = self.service._streams_of.get(self.conn.client_id, {})
        assert set(streams) == set(self.streaming)
        assert set(self.service.wanted_trace_columns.tolist()) <= set(range(
            self.device.collection.trace_width))


TestProtocolMachine = ProtocolMachine.TestCase
TestProtocolMachine.settings = settings(settings.get_profile("astcom"),
    max_examples=80, stateful_step_count=40, deadline=None)
