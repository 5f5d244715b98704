"""`astcom`: list, get, set, call and stream the variables of any ASTCom endpoint.

Thin commands over `astcom_client.Client`; errors go to stderr with a non-zero exit
code (1: the endpoint refused, 2: bad arguments or no connection).
"""

from __future__ import annotations

import asyncio
import csv
import json
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from .client import Client
from .exceptions import AstcomError, ConnectionClosed, InvalidValue
from .text import parse_signature, to_jsonable, value_from_text, value_to_text
from .url import parse_url

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Discover, read, write, call and stream the variables of an ASTCom endpoint.")
out = Console()
err = Console(stderr=True)

URL_HELP = "Endpoint address: ws://HOST:PORT, wss://HOST:PORT, tcp://HOST:PORT or tls://HOST:PORT."
Url = Annotated[str, typer.Argument(help=URL_HELP, show_default=False)]
Password = Annotated[str | None, typer.Option(
    "--password", "-p", envvar="ASTCOM_PASSWORD", show_envvar=True,
    help="Password of the observer or operator role (never sent in clear).")]
Role = Annotated[str | None, typer.Option(
    "--role", help="Ask for at most this role: observer or operator.")]
Cafile = Annotated[Path | None, typer.Option(
    "--cafile", help="PEM file of the authority that signed the endpoint's certificate (wss://, tls://).")]
Timeout = Annotated[float, typer.Option("--timeout", min=0.1, help="Seconds to wait for each reply.")]
Json = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


def _fail(message: str, code: int) -> typer.Exit:
    err.print(f"[red]error:[/red] {message}", highlight=False)
    return typer.Exit(code)


def _run(coro: Any) -> Any:
    """Run one command's coroutine; turn every expected failure into a message and exit code."""
    try:
        return asyncio.run(coro)
    except ValueError as exc:
        if isinstance(exc, AstcomError) and not isinstance(exc, InvalidValue):
            raise _fail(f"{exc} (code {exc.code})", 1) from None
        raise _fail(str(exc), 2) from None
    except ConnectionClosed as exc:
        raise _fail(str(exc), 2) from None
    except AstcomError as exc:
        raise _fail(f"{exc} (code {exc.code}){_cli_hint(exc)}", 1) from None
    except (ConnectionError, OSError, TimeoutError) as exc:
        raise _fail(f"connection failed: {exc or type(exc).__name__}", 2) from None


def _cli_hint(exc: AstcomError) -> str:
    """Name the astcom command that does what the refused request could not."""
    text = str(exc)
    if "is a function, not a variable" in text:
        return "; use `astcom call URL NAME [ARGS...]`"
    if "is a variable, not a function" in text:
        return "; use `astcom get`, `astcom set` or `astcom stream`"
    return ""


async def _connect(url: str, password: str | None, role: str | None, cafile: Path | None,
                   timeout: float) -> Client:
    parse_url(url)
    if role not in (None, "observer", "operator"):
        raise ValueError(f"--role must be observer or operator, got {role!r}")
    return await Client.connect(url, password=password, role=role, name="astcom-cli",
                                cafile=str(cafile) if cafile else None, timeout_s=timeout)


def _print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(to_jsonable(obj), indent=2) + "\n")


@app.command("list")
def list_command(url: Url, prefix: Annotated[str, typer.Option(
                     "--prefix", help="Only names starting with this text, e.g. axis.az.")] = "",
                 password: Password = None, role: Role = None, cafile: Cafile = None,
                 timeout: Timeout = 10.0, as_json: Json = False) -> None:
    """List every variable and function: name, type, kind, access, unit, doc, and the range a
    parameter may be written to (min..max, when it declares one)."""
    async def main() -> list[Any]:
        async with await _connect(url, password, role, cafile, timeout) as client:
            return await client.list(prefix)

    entries = _run(main())
    if as_json:
        _print_json([e.as_dict() for e in entries])
        return
    if not out.is_terminal:
        # a pipe or a file: one whole entry per line, tab-separated, for grep and cut
        for e in entries:
            sys.stdout.write("\t".join((e.name, e.type, e.kind, e.access, e.unit, e.doc,
                                        _range_text(e))) + "\n")
        return
    table = Table(title=f"{len(entries)} entries")
    table.add_column("name", no_wrap=True, overflow="fold")  # a name is never cut short
    for column in ("type", "kind", "access", "unit", "range"):
        table.add_column(column)
    table.add_column("doc", ratio=1)
    for e in entries:
        table.add_row(e.name, e.type, e.kind, e.access, e.unit, _range_text(e), e.doc)
    out.print(table)


def _range_text(entry: Any) -> str:
    """`min..max` of a bounded entry ('' when it declares none)."""
    if entry.min is None and entry.max is None:
        return ""
    lo = "" if entry.min is None else f"{entry.min:g}"
    hi = "" if entry.max is None else f"{entry.max:g}"
    return f"{lo}..{hi}"


@app.command("get")
def get_command(url: Url, names: Annotated[list[str], typer.Argument(
                    help="Variable names, all read at the same tick.", show_default=False)],
                password: Password = None, role: Role = None, cafile: Cafile = None,
                timeout: Timeout = 10.0, as_json: Json = False) -> None:
    """Read variables (all at one tick of the device loop)."""
    async def main() -> tuple[dict[str, Any], int, int]:
        async with await _connect(url, password, role, cafile, timeout) as client:
            return await client.read_at(names)

    values, tick, t_us = _run(main())
    if as_json:
        _print_json({"tick": tick, "t_us": t_us, "values": values})
        return
    table = Table("name", "value", title=f"tick {tick}, t_us {t_us}")
    for name, value in values.items():
        table.add_row(name, value_to_text(value))
    out.print(table)


async def _entry_type(client: Client, name: str) -> str:
    entries = [e for e in await client.list(name) if e.name == name]
    if not entries:
        from .exceptions import UnknownName

        raise UnknownName(f"no variable or function named {name!r} (see `astcom list URL`)")
    return entries[0].type


@app.command("set")
def set_command(url: Url, name: Annotated[str, typer.Argument(help="Variable name.", show_default=False)],
                value: Annotated[str, typer.Argument(
                    help="New value: 1.5, true, \\[1, 2, 3] (arrays as JSON), {\"a\": 1} (structs).",
                    show_default=False)],
                password: Password = None, role: Role = None, cafile: Cafile = None,
                timeout: Timeout = 10.0, as_json: Json = False) -> None:
    """Write one variable (needs the operator role)."""
    async def main() -> tuple[Any, int]:
        async with await _connect(url, password, role, cafile, timeout) as client:
            parsed = value_from_text(await _entry_type(client, name), value, where=name)
            return parsed, await client.write({name: parsed})

    parsed, tick = _run(main())
    if as_json:
        _print_json({"name": name, "value": parsed, "tick": tick})
    else:
        out.print(f"{name} = {value_to_text(parsed)}  (applied after tick {tick})", highlight=False)


@app.command("call")
def call_command(url: Url, name: Annotated[str, typer.Argument(help="Function name.", show_default=False)],
                 args: Annotated[list[str] | None, typer.Argument(
                     help="Arguments in the order of the function's type (see `astcom list`).",
                     show_default=False)] = None,
                 password: Password = None, role: Role = None, cafile: Cafile = None,
                 timeout: Timeout = 10.0, as_json: Json = False) -> None:
    """Invoke a device function and print what it returns (needs the operator role)."""
    given = args or []

    async def main() -> Any:
        async with await _connect(url, password, role, cafile, timeout) as client:
            signature = await _entry_type(client, name)
            if not signature.startswith("("):
                raise ValueError(f"{name} is a variable, not a function; use `astcom get`")
            arg_types, _ = parse_signature(signature)
            if len(given) != len(arg_types):
                raise ValueError(f"{name} takes {len(arg_types)} arguments {signature}, "
                                 f"got {len(given)}")
            parsed = [value_from_text(t, text, where=f"{name}({arg})")
                      for (arg, t), text in zip(arg_types, given, strict=True)]
            return await client.invoke(name, *parsed)

    result = _run(main())
    if as_json:
        _print_json({"name": name, "value": result})
    elif result is not None:  # a function that returns nothing prints nothing
        out.print(value_to_text(result), highlight=False)


@app.command("stream")
def stream_command(url: Url, names: Annotated[list[str], typer.Argument(
                       help="Signals to stream.", show_default=False)],
                   rate: Annotated[float, typer.Option(
                       "--rate", min=0.0, help="Samples per second (rounded to loop rate / k).")] = 10.0,
                   duration: Annotated[float, typer.Option(
                       "--duration", min=0.0, help="Seconds to stream.")] = 5.0,
                   out_file: Annotated[Path | None, typer.Option(
                       "--out", help="Write every sample to this CSV file (t_us, tick, signals).")] = None,
                   show: Annotated[bool, typer.Option(
                       "--show", help="Print every sample as it arrives.")] = False,
                   password: Password = None, role: Role = None, cafile: Cafile = None,
                   timeout: Timeout = 10.0, as_json: Json = False) -> None:
    """Stream signals for a while, like camonitor; print counts and losses at the end."""
    if out_file is not None and out_file.parent and not out_file.parent.exists():
        raise _fail(f"--out: directory {out_file.parent} does not exist", 2)

    async def main() -> dict[str, Any]:
        async with await _connect(url, password, role, cafile, timeout) as client:
            stream = await client.stream(names, rate)
            writer = None
            handle = out_file.open("w", newline="") if out_file else None
            try:
                if handle is not None:
                    writer = csv.writer(handle)
                    writer.writerow(["t_us", "tick", *stream.names])
                start = time.monotonic()
                samples = lost = packets = 0
                ended = False
                while (left := duration - (time.monotonic() - start)) > 0:
                    try:
                        packet = await stream.get(timeout_s=left)
                    except TimeoutError:
                        break
                    except StopAsyncIteration:  # the endpoint closed the connection
                        ended = True
                        break
                    samples, lost, packets = samples + packet.n, lost + packet.lost, packets + 1
                    if writer is not None:
                        for t_us, tick, row in zip(packet.t_us.tolist(), packet.ticks.tolist(),
                                                   packet.values.tolist(), strict=True):
                            writer.writerow([t_us, tick, *row])
                    if show:
                        for t_us, row in zip(packet.t_us.tolist(), packet.values, strict=True):
                            out.print(t_us, *(f"{v:.9g}" for v in row.tolist()), highlight=False)
                elapsed = time.monotonic() - start
                if not ended:
                    await stream.stop()
            finally:
                if handle is not None:
                    handle.close()
            return {"samples": {n: samples for n in stream.names}, "lost": lost,
                    "rate_hz": stream.rate_hz, "duration_s": round(elapsed, 6),
                    "packets": packets, "out": str(out_file) if out_file else None,
                    "endpoint_closed": ended}

    summary = _run(main())
    if summary["endpoint_closed"]:
        err.print(f"[red]error:[/red] the endpoint closed the connection after "
                  f"{summary['duration_s']:.2f} s; the samples received are counted below",
                  highlight=False)
    if as_json:
        _print_json(summary)
    else:
        _print_stream_summary(summary)
    if summary["endpoint_closed"]:
        raise typer.Exit(1)


def _print_stream_summary(summary: dict[str, Any]) -> None:
    table = Table("signal", "samples", title=(f"{summary['rate_hz']:g} Hz for "
                                               f"{summary['duration_s']:.2f} s, lost {summary['lost']}"))
    for name, count in summary["samples"].items():
        table.add_row(name, str(count))
    out.print(table)


@app.command("relay")
def relay_command(
        serial: Annotated[str | None, typer.Option(
            "--serial", help="The device's framed link on a tty or pty, e.g. /dev/ttyUSB0.")] = None,
        tcp: Annotated[str | None, typer.Option(
            "--tcp", help="The device's framed link as a TCP stream, HOST:PORT.")] = None,
        listen: Annotated[list[str] | None, typer.Option(
            "--listen", help="Where clients connect: ws://HOST:PORT or tcp://HOST:PORT "
                             "(repeatable; port 0 picks a free one).")] = None,
        allowed_origin: Annotated[list[str] | None, typer.Option(
            "--allowed-origin", help="Web pages that may connect (default: loopback pages); "
                                     "'*' for any.")] = None,
        queue_packets: Annotated[int, typer.Option(
            "--queue-packets", min=1, help="Stream packets queued per slow client before the "
                                           "oldest is dropped.")] = 256,
        link_timeout: Annotated[float, typer.Option(
            "--link-timeout", min=0.5, help="Seconds without a frame from the device (it "
                                            "answers a PING every second) before the link "
                                            "counts as lost and its clients get ERR 503.")] = 3.0
        ) -> None:
    """Carry one device link (serial/SPI or TCP, framed as in the protocol's §11) to many clients.

    Every client gets its own session on the device (handshake, password, streams); the
    relay only carries frames. Link loss or a device restart closes the clients with
    ERR 503 saying why. Stop with Ctrl-C.
    """
    from .relay import Relay, RelayConfig

    if (serial is None) == (tcp is None):
        raise _fail("give exactly one device link: --serial DEV or --tcp HOST:PORT", 2)
    try:
        config = RelayConfig(serial=serial, tcp=tcp, listen=tuple(listen or ["ws://127.0.0.1:8765"]),
                             allowed_origins=tuple(allowed_origin) if allowed_origin else None,
                             queue_packets=queue_packets, link_timeout_s=link_timeout)
        for url in config.listen:
            parse_url(url)
    except ValueError as exc:
        raise _fail(str(exc), 2) from None

    async def run() -> None:
        relay = Relay(config)
        urls = await relay.start()
        link = serial or f"tcp://{tcp}"
        state = "up" if relay.link_up.is_set() else f"down ({relay.down_reason})"
        print(f"relay listening on {' '.join(urls)} for the device on {link} (link {state})",
              flush=True)
        try:
            await asyncio.Event().wait()
        finally:
            await relay.close()

    try:
        asyncio.run(run())
    except KeyboardInterrupt:
        pass
    except OSError as exc:
        raise _fail(f"the relay cannot start: {exc}", 2) from None


def main() -> None:
    """Run the `astcom` command line."""
    np.set_printoptions(precision=9)
    app()


if __name__ == "__main__":
    main()
