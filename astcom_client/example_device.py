"""A small device for tests, the demo and the benchmarks: signals, parameters, functions
and a tick loop, served by an Endpoint like the mount emulator's.

Signals (traced, one value per tick): ``wave.sine`` = amplitude·sin(2π·f·t) + offset,
``wave.cosine``, ``counter`` (the tick number), ``pair.diff`` = pair.a − pair.b (stays 0
when pair.a and pair.b are always written together), and ``extra.sNN`` sines for load.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field

import numpy as np

from .endpoint import Endpoint
from .registry import Collection, astcom_field

__all__ = ["ExampleDevice", "Power"]

P_AMPLITUDE, P_FREQUENCY_HZ, P_OFFSET, P_PAIR_A, P_PAIR_B = range(5)
MAX_BLOCK_S = 0.1  # a late loop catches up in blocks of at most this much time


@dataclass
class Limits:
    """Nested parameters, registered recursively under power.limits."""

    current_a: float = astcom_field(2.5, kind="parameter", access="rw", unit="A",
                                    doc="Current limit of the drive")
    enabled: bool = astcom_field(True, kind="parameter", access="rw", doc="Drive enabled")


@dataclass
class Power:
    """A dataclass registered with Collection.register (like AST_VARIABLE_DEFINE)."""

    voltage_v: float = astcom_field(24.0, unit="V", doc="Bus voltage")
    mode: str = astcom_field("idle", kind="parameter", access="rw", doc="Power mode name")
    limits: Limits = astcom_field(default_factory=Limits, doc="Drive limits")
    note: str = "not published"  # no astcom_field: stays private


@dataclass
class _State:
    label: str = "example"
    site: dict = field(default_factory=lambda: {"lat_deg": 45.0, "lon_deg": 6.0})


class ExampleDevice:
    """A device with a sine generator, a counter and a few parameters and functions."""

    def __init__(self, *, loop_rate_hz: float = 1000.0, n_extra_signals: int = 0,
                 start_t_us: int | None = None) -> None:
        self.loop_rate_hz = float(loop_rate_hz)
        self.start_t_us = time.time_ns() // 1000 if start_t_us is None else start_t_us
        self.tick = 0
        self.params = np.array([1.0, 5.0, 0.0, 0.0, 0.0])
        self.gains = np.array([1.0, 0.1, 0.01])
        self.last = np.zeros(4 + n_extra_signals)  # sine, cosine, counter, diff, extras
        self.power = Power()
        self.state = _State()
        self.calls = 0
        self._counter_base = 0
        self.collection = self._build_collection(n_extra_signals)

    def _build_collection(self, n_extra: int) -> Collection:
        c = Collection()
        last = self.last
        c.add_slot("wave.sine", last, 0, type="f64", unit="V", traced=True,
                   doc="amplitude*sin(2*pi*frequency_hz*t) + offset")
        c.add_slot("wave.cosine", last, 1, type="f64", unit="V", traced=True,
                   doc="amplitude*cos(2*pi*frequency_hz*t)")
        c.add_slot("counter", last, 2, type="i64", traced=True, doc="Tick number")
        c.add_slot("pair.diff", last, 3, type="f64", traced=True,
                   doc="pair.a - pair.b: zero while both are written together")
        for i in range(n_extra):
            c.add_slot(f"extra.s{i:02d}", last, 4 + i, type="f64", traced=True,
                       doc=f"sin(2*pi*frequency_hz*t + {i})")
        p = self.params
        c.add_slot("wave.amplitude", p, P_AMPLITUDE, type="f64", kind="parameter", access="rw",
                   unit="V", doc="Sine amplitude", min_value=0.0, max_value=100.0)
        c.add_slot("wave.frequency_hz", p, P_FREQUENCY_HZ, type="f64", kind="parameter",
                   access="rw", unit="Hz", doc="Sine frequency", min_value=0.0,
                   max_value=self.loop_rate_hz / 2)
        c.add_slot("wave.offset", p, P_OFFSET, type="f64", kind="parameter", access="rw",
                   unit="V", doc="Sine offset")
        c.add_slot("pair.a", p, P_PAIR_A, type="f64", kind="parameter", access="rw",
                   doc="Written together with pair.b")
        c.add_slot("pair.b", p, P_PAIR_B, type="f64", kind="parameter", access="rw",
                   doc="Written together with pair.a")
        c.add_slot("gains", self.gains, slice(0, 3), type="f64[3]", kind="parameter",
                   access="rw", doc="PID gains kp, ki, kd", min_value=0.0, max_value=1000.0)
        c.add_variable("label", "str", kind="parameter", access="rw", doc="Device label",
                       get=lambda: self.state.label, set=lambda v: setattr(self.state, "label", v))
        c.add_variable("site", "{lat_deg:f64,lon_deg:f64}", kind="parameter", access="rw",
                       unit="deg", doc="Site position", get=lambda: self.state.site,
                       set=lambda v: setattr(self.state, "site", v))
        c.register(self.power, prefix="power")
        c.add_function("counter.reset", self._reset, returns="i64",
                       doc="Restart the counter at 0; returns the tick it had reached")
        c.add_function("math.add", lambda a, b: a + b, args=[("a", "f64"), ("b", "f64")],
                       returns="f64", doc="Return a + b")
        c.add_function("math.sum", lambda x: float(np.sum(x)), args=[("x", "f64[]")],
                       returns="f64", doc="Return the sum of an array")
        c.add_function("device.fail", self._fail, doc="Always raise (to test error replies)")
        c.add_function("device.wait", self._wait, args=[("seconds", "f64")], returns="f64",
                       doc="Sleep without blocking the loop, return the seconds slept")
        return c

    def _reset(self) -> int:
        self.calls += 1
        reached, self._counter_base = self.tick, self.tick
        return reached

    @staticmethod
    def _fail() -> None:
        raise RuntimeError("this function always fails")

    @staticmethod
    async def _wait(seconds: float) -> float:
        await asyncio.sleep(min(max(seconds, 0.0), 5.0))
        return seconds

    # -- the loop ------------------------------------------------------------------------------
    def t_us_of(self, tick: int) -> int:
        """Return the mount time (µs) of `tick`."""
        return self.start_t_us + round(tick * 1e6 / self.loop_rate_hz)

    def step(self, n_ticks: int) -> np.ndarray:
        """Compute ticks [tick, tick + n_ticks); return their trace and advance."""
        ticks = self.tick + np.arange(n_ticks)
        amp, freq, offset, a, b = self.params
        phase = 2 * np.pi * freq * ticks / self.loop_rate_hz
        trace = np.empty((n_ticks, len(self.last)))
        trace[:, 0] = amp * np.sin(phase) + offset
        trace[:, 1] = amp * np.cos(phase)
        trace[:, 2] = ticks - self._counter_base
        trace[:, 3] = a - b
        for i in range(4, len(self.last)):
            trace[:, i] = np.sin(phase + (i - 4))
        self.last[:] = trace[-1]
        self.tick += n_ticks
        return trace

    def advance(self, endpoint: Endpoint | None, n_ticks: int) -> None:
        """Compute `n_ticks` ticks and publish them (simulated time: as fast as asked)."""
        first = self.tick
        trace = self.step(n_ticks)
        if endpoint is not None:
            endpoint.publish(first, self.t_us_of(first), n_ticks, trace)

    async def run(self, endpoint: Endpoint, *, block_s: float = 0.002,
                  duration_s: float | None = None) -> None:
        """Run in real time (ticks due from the monotonic clock), publishing every block."""
        t0 = time.monotonic()
        tick0 = self.tick
        max_block = max(1, int(MAX_BLOCK_S * self.loop_rate_hz))
        while duration_s is None or time.monotonic() - t0 < duration_s:
            due = int((time.monotonic() - t0) * self.loop_rate_hz) - (self.tick - tick0)
            while due > 0:
                n = min(due, max_block)
                self.advance(endpoint, n)
                due -= n
            await asyncio.sleep(block_s)


async def serve_example(urls: list[str], *, loop_rate_hz: float = 1000.0,
                        passwords: dict[str, str] | None = None,
                        duration_s: float | None = None, n_extra_signals: int = 0) -> None:
    """Serve an ExampleDevice on `urls` and run its loop (for trying the `astcom` CLI)."""
    from .endpoint import EndpointConfig

    device = ExampleDevice(loop_rate_hz=loop_rate_hz, n_extra_signals=n_extra_signals)
    endpoint = Endpoint(device.collection, EndpointConfig(loop_rate_hz=loop_rate_hz,
                                                          passwords=passwords, name="example"))
    for url in urls:
        print(f"serving the example device on {await endpoint.serve(url)}", flush=True)
    try:
        await device.run(endpoint, duration_s=duration_s)
    finally:
        await endpoint.close()


def main() -> None:
    """Run `python -m astcom_client.example_device [URL...] [--password P] [--rate HZ]`."""
    import typer

    def serve(urls: list[str] = typer.Argument(None, help="ws://, tcp:// URLs to listen on."),  # noqa: B008
              password: str = typer.Option(None, envvar="ASTCOM_PASSWORD",
                                           help="Operator password (none: no authentication)."),
              rate: float = typer.Option(1000.0, help="Loop rate in Hz."),
              duration: float = typer.Option(None, help="Stop after this many seconds.")) -> None:
        passwords = {"operator": password} if password else None
        asyncio.run(serve_example(urls or ["ws://127.0.0.1:8765"], loop_rate_hz=rate,
                                  passwords=passwords, duration_s=duration))

    typer.run(serve)


if __name__ == "__main__":
    main()
