"""The sans-I/O core: handshake, state table and framing, driven byte by byte in memory."""

import ast
import dataclasses
from pathlib import Path

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import astcom_client
from astcom_client.auth import Authenticator, Role, client_mac
from astcom_client.codec import Codec
from astcom_client.commands import COMMANDS, Command, decode_request
from astcom_client.exceptions import LimitExceeded
from astcom_client.framing import FrameReader, frame_bytes
from astcom_client.protocol import (
    SERVER_TRANSITIONS,
    ClientConnection,
    ClientState,
    Failure,
    Ready,
    RequestReceived,
    ServerConnection,
    ServerOptions,
    ServerState,
)

PASSWORDS = {"operator": "op", "observer": "obs"}
ASTCOM = settings.get_profile("astcom")
SANS_IO = ["protocol.py", "commands.py", "codec.py", "service.py", "auth.py", "types.py",
           "registry.py", "framing.py", "exceptions.py", "url.py"]


def server(passwords=PASSWORDS) -> ServerConnection:
    return ServerConnection(ServerOptions(Authenticator(passwords), Codec()))


def pump(a, b) -> list:
    """Move every queued frame from a to b; return b's events."""
    events = []
    while (frame := a.next_frame()) is not None:
        events += b.receive_frame(frame)
    return events


@pytest.mark.parametrize("module", SANS_IO)
def test_protocol_core_imports_neither_asyncio_nor_socket(module: str) -> None:
    tree = ast.parse((Path(astcom_client.__file__).parent / module).read_text())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            imported.add(node.module.split(".")[0])
    assert not imported & {"asyncio", "socket", "websockets", "ssl"}


def test_a_client_and_a_server_core_complete_the_handshake_in_memory() -> None:
    srv = server()
    cli = ClientConnection(Codec(), password="obs")
    cli.start()
    assert pump(cli, srv) == [] and srv.state is ServerState.AWAIT_AUTH
    assert pump(srv, cli) == [] and cli.state is ClientState.AUTH_SENT
    assert pump(cli, srv) == [] and srv.role is Role.OBSERVER
    (ready,) = pump(srv, cli)
    assert isinstance(ready, Ready) and ready.role is Role.OBSERVER
    assert cli.state is ClientState.READY and srv.state is ServerState.READY


def test_a_client_core_refuses_an_endpoint_that_cannot_prove_the_password() -> None:
    srv = ServerConnection(ServerOptions(Authenticator({"operator": "same"}), Codec()))
    cli = ClientConnection(Codec(), password="same")
    cli.start()
    pump(cli, srv)
    pump(srv, cli)
    pump(cli, srv)
    frame = srv.next_frame()
    reply = msgpack.unpackb(frame)
    reply[2]["proof"] = b"\x00" * 32  # an impostor that accepted anything
    (failure,) = cli.receive_frame(msgpack.packb(reply, use_bin_type=True))
    assert isinstance(failure, Failure) and "prove" in failure.error.message


def test_the_hello_request_has_the_documented_bytes() -> None:
    cli = ClientConnection(Codec(), client_name="x")
    cli.start()
    assert cli.next_frame() == bytes.fromhex(
        "93a548454c4c4f0182a776657273696f6ea3312e30a6636c69656e74a178")


def test_the_mac_is_hmac_sha256_over_the_documented_message() -> None:
    import hashlib
    import hmac

    sn, cn = bytes(range(32)), bytes(range(32, 64))
    expected = hmac.new(b"pw", b"ASTCom-1 client\x00" + sn + cn, hashlib.sha256).digest()
    assert client_mac("pw", sn, cn) == expected
    role, proof = Authenticator({"operator": "pw"}).verify(sn, cn, expected)
    assert role is Role.OPERATOR
    assert proof == hmac.new(b"pw", b"ASTCom-1 server\x00" + sn + cn, hashlib.sha256).digest()


def test_the_state_table_allows_only_hello_ping_and_bye_first() -> None:
    assert set(SERVER_TRANSITIONS[ServerState.AWAIT_HELLO]) == {"HELLO", "PING", "BYE"}
    assert set(SERVER_TRANSITIONS[ServerState.AWAIT_AUTH]) == {"AUTH", "PING", "BYE"}
    assert set(SERVER_TRANSITIONS[ServerState.READY]) == set(COMMANDS) - {"HELLO", "AUTH"}


def test_without_passwords_hello_grants_the_operator_role() -> None:
    srv = server(passwords=None)
    cli = ClientConnection(Codec())
    cli.start()
    pump(cli, srv)
    (ready,) = pump(srv, cli)
    assert ready.role is Role.OPERATOR and srv.state is ServerState.READY


def _example(cls: type[Command]) -> Command:
    values = {"version": "1.0", "client": "c", "cnonce": b"n" * 16, "mac": b"m" * 32,
              "role": "observer", "prefix": "a.", "names": ["a", "b"], "msg": 3,
              "values": [1.0, [1, 2]], "name": "f", "args": [1, "x"], "rate_hz": 10.0}
    return cls(**{f.name: values[f.name] for f in dataclasses.fields(cls)})


@pytest.mark.parametrize("cls", list(COMMANDS.values()), ids=list(COMMANDS))
def test_every_command_round_trips_through_its_frame(cls: type[Command]) -> None:
    command = _example(cls)
    codec = Codec()
    seq, decoded = decode_request(codec.decode(codec.encode(command.to_frame(41))))
    assert seq == 41 and decoded == command


@pytest.mark.parametrize("cls", [c for c in COMMANDS.values() if c.SCHEMA], ids=lambda c: c.OP)
def test_every_command_names_the_field_of_the_wrong_type(cls: type[Command]) -> None:
    args = _example(cls).to_args()
    field = next(iter(cls.SCHEMA))
    args[field] = {"not": "right"}
    with pytest.raises(ValueError, match=repr(field)):
        cls.from_args(args)


@ASTCOM
@given(st.lists(st.binary(max_size=50), max_size=8), st.data())
def test_frames_survive_any_split_of_the_tcp_byte_stream(frames: list, data) -> None:
    stream = b"".join(frame_bytes(f) for f in frames)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    reader = FrameReader(max_frame_bytes=100)
    got = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += reader.feed(stream[start:end])
    assert got == frames and reader.buffered == 0


def test_an_announced_frame_beyond_the_limit_is_refused_before_it_arrives() -> None:
    with pytest.raises(LimitExceeded, match="limit"):
        FrameReader(max_frame_bytes=10).feed(b"\x00\x00\x00\x0b")


@ASTCOM
@given(st.binary(max_size=300))
def test_random_bytes_into_the_server_core_give_errors_never_exceptions(data: bytes) -> None:
    srv = server()
    events = srv.receive_frame(data)
    assert not any(isinstance(e, RequestReceived) for e in events)
    replies = []
    while (frame := srv.next_frame()) is not None:
        replies.append(msgpack.unpackb(frame))
    assert replies and all(r[0] in ("ERR", "OK") for r in replies)


frames = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 2**64 - 1) | st.floats() | st.text(max_size=12)
    | st.binary(max_size=12) | st.sampled_from(list(COMMANDS)),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["version", "msg", "names", "cnonce", "mac", "values", "x"]), inner,
        max_size=4), max_leaves=15)


@ASTCOM
@given(st.lists(frames, min_size=1, max_size=6))
def test_random_msgpack_frames_after_login_never_break_the_core(objs: list) -> None:
    srv = server(passwords=None)
    codec = Codec()
    srv.receive_frame(codec.encode(["HELLO", 0, {"version": "1.0"}]))
    for obj in objs:
        for event in srv.receive_frame(codec.encode(obj)):
            if isinstance(event, RequestReceived):
                assert event.command.OP in COMMANDS
        if srv.state is ServerState.CLOSED:
            break
    while srv.next_frame() is not None:
        pass


def test_the_server_nonce_is_fresh_for_every_connection() -> None:
    nonces = set()
    for _ in range(5):
        srv = server()
        srv.receive_frame(Codec().encode(["HELLO", 1, {"version": "1.0"}]))
        nonces.add(msgpack.unpackb(srv.next_frame())[2]["nonce"])
    assert len(nonces) == 5 and all(len(n) == 32 for n in nonces)
