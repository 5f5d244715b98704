"""1000 random commands from 4 WebSocket clients at once: one owner of the mount, every answer once.

The VSS and the emulator run in lockstep simulated time (×PACE at most) on an
event loop in a thread; four clients on real loopback WebSockets each send their
share of random slew / track / satellite / park / stop commands at random 0–100 ms
wall spacing, without waiting for answers (several pending per client). At the
end one more `stop` is sent and the mount is watched for a minute of mount time.

Goals (issue 11): 0 orphaned operations (no mount command from an operation after
a newer one has sent one: the link logs which operation sent each command), 0
requests unanswered or answered twice, 0 motion after the final stop (no motion
command, encoders still, state HOLDING/OFF). Printed beside the answer latency of
`ping` measured in the same run (the bare API round trip).

    python benchmarks/bench_vss_concurrency.py [--commands 1000] [--clients 4] [--seed 1]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import random
import threading
import time
from collections import Counter

import numpy as np
from websockets.asyncio.client import connect

from catalogs import load_tle_file, sample_tle_path
from virtualstar.astro import UtcTimes, load_site
from virtualstar.launcher import embedded_vss
from virtualstar.lockstep import LockstepClock, LockstepEventLoop
from virtualstar.server.supervisor import operations_of_tasks

START = "2024-05-18T19:40:00Z"
PACE = 20.0
MOTION_ROLES = {"power_on", "power_off", "stop", "slew", "traj_init", "traj_start", "traj_reset",
                "traj_push", "reset_faults"}
STILL_RAD = math.radians(10 / 3600)


def random_command(rng: random.Random, tle: str) -> tuple[str, dict]:
    star = rng.choice(["Vega", "Arcturus", "Deneb", "Altair"])
    kind = rng.choices(["slew_star", "slew_altaz", "track", "track_wait", "sat", "park", "stop"],
                       weights=[3, 3, 3, 2, 1, 1, 3])[0]
    if kind == "slew_star":
        return "slew", {"star": star}
    if kind == "slew_altaz":
        return "slew", {"altaz": f"{rng.uniform(0, 360):.2f} {rng.uniform(15, 85):.2f}"}
    if kind == "track":
        return "track", {"star": star}
    if kind == "track_wait":
        return "track", {"star": star, "duration_s": rng.choice([5.0, 20.0]), "wait": True}
    if kind == "sat":
        return "track", {"tle": tle, "sat": "ISS"}
    if kind == "park":
        return "park", {"wait": rng.random() < 0.5}
    return "stop", {}


class ServerThread:
    """The emulator + VSS on a lockstep loop in a thread (the clients stay outside it)."""

    def __init__(self) -> None:
        self.clock = LockstepClock(int(UtcTimes.from_iso([START]).to_unix_us()[0]), pace=PACE)
        self.loop = LockstepEventLoop(self.clock)
        self.ready = threading.Event()
        self.stopping: asyncio.Event | None = None
        self.vss = None
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self._main(),),
                                       daemon=True)

    async def _main(self) -> None:
        self.stopping = asyncio.Event()
        async with embedded_vss(clock=self.clock, site=load_site(),
                                listen="ws://127.0.0.1:0") as vss:
            self.vss = vss
            self.ready.set()
            await self.stopping.wait()

    def start(self) -> str:
        self.thread.start()
        self.ready.wait(60)
        return self.vss.url

    def call(self, coro, timeout_s: float = 60.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout_s)

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self.stopping.set)
        self.thread.join(30)


async def client_session(url: str, index: int, sends: list[tuple[str, dict]], rng: random.Random,
                         answers: Counter, latencies: dict, sent: list, outcomes: Counter) -> None:
    async with connect(url, max_size=1 << 24) as ws:
        await ws.recv()  # hello
        waiting: dict[int, float] = {}
        prefix = (index + 1) * 1_000_000  # request ids unique across clients (shared Counter)

        async def reader() -> None:
            async for text in ws:
                doc = json.loads(text)
                if "id" in doc and doc["id"] in waiting:
                    answers[doc["id"]] += 1
                    outcomes[doc["error"]["code"] if not doc.get("ok") else "ok"] += 1
                    latencies.setdefault(sent_cmd[doc["id"]], []).append(
                        time.perf_counter() - waiting[doc["id"]])
                elif "id" in doc:
                    answers[doc["id"]] += 1  # an answer to nothing, or a second one

        sent_cmd: dict[int, str] = {}
        task = asyncio.ensure_future(reader())
        for k, (cmd, params) in enumerate(sends):
            rid = prefix + k
            sent_cmd[rid] = cmd
            waiting[rid] = time.perf_counter()
            sent.append(rid)
            await ws.send(json.dumps({"id": rid, "cmd": cmd, "params": params}))
            await asyncio.sleep(rng.uniform(0.0, 0.1))
        deadline = time.perf_counter() + 300.0  # every answer within this, or it counts as lost
        while not all(answers[i] for i in waiting) and time.perf_counter() < deadline:
            await asyncio.sleep(0.05)
        task.cancel()


async def ping_latency(url: str, n: int = 200) -> list[float]:
    out = []
    async with connect(url) as ws:
        await ws.recv()
        for k in range(n):
            t0 = time.perf_counter()
            await ws.send(json.dumps({"id": k, "cmd": "ping"}))
            while "id" not in json.loads(await ws.recv()):
                pass
            out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--commands", type=int, default=1000)
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    tle = f"{rec.name}\n{rec.line1}\n{rec.line2}\n"
    rng = random.Random(args.seed)
    plans = [[random_command(rng, tle) for _ in range(args.commands // args.clients)]
             for _ in range(args.clients)]
    server = ServerThread()
    url = server.start()
    telescope = server.vss.server.telescope
    answers: Counter = Counter()
    outcomes: Counter = Counter()
    latencies: dict[str, list[float]] = {}
    sent: list[int] = []
    wall0 = time.perf_counter()
    mount0 = server.clock.now_us

    async def clients() -> list[float]:
        pings = asyncio.ensure_future(ping_latency(url))
        await asyncio.gather(*(client_session(url, i, plan, random.Random(args.seed * 100 + i),
                                              answers, latencies, sent, outcomes)
                               for i, plan in enumerate(plans)))
        return await pings

    ping = asyncio.run(clients())
    wall = time.perf_counter() - wall0
    mount_s = (server.clock.now_us - mount0) / 1e6
    # the final stop, then a minute of mount time watched from the emulator's side
    final: dict = {}

    async def final_stop() -> None:
        async with connect(url) as ws:
            await ws.recv()
            await ws.send(json.dumps({"id": "final", "cmd": "stop"}))
            while (doc := json.loads(await ws.recv())).get("id") != "final":
                pass
            final["answer"] = doc

    asyncio.run(final_stop())
    calls_at_stop = telescope.link.calls[-1].seq if telescope.link.calls else 0
    last_op = telescope.supervisor.operations_started

    async def watch() -> tuple[list, list]:
        observer = await server.vss.emulator.connect_in_memory(name="bench-observer")
        reads = []
        for _ in range(13):
            v, _, _ = await observer.read_at(["axis.az.position", "axis.el.position",
                                              "mount.state_name"])
            reads.append(v)
            await server.clock.sleep(5.0)
        await observer.close()
        names = [t.get_name() for t in asyncio.all_tasks() if not t.done()]
        return reads, names

    reads, names = server.call(watch(), 120.0)
    calls = list(telescope.link.calls)
    server.stop()

    # orphans: a mount command from an operation after a newer one had sent one
    newest, orphans = 0, 0
    for c in calls:
        if c.role in MOTION_ROLES and c.operation is not None:
            if c.operation < newest:
                orphans += 1
            newest = max(newest, c.operation)
    live_ops = operations_of_tasks(names)
    after_stop = [c for c in calls if c.seq > calls_at_stop and c.role in MOTION_ROLES]
    az = np.array([r["axis.az.position"] for r in reads])
    el = np.array([r["axis.el.position"] for r in reads])
    moved = max(np.ptp(az), np.ptp(el))
    states = {r["mount.state_name"] for r in reads}
    unanswered = sum(1 for rid in sent if answers[rid] == 0)
    twice = sum(1 for rid in sent if answers[rid] > 1)
    lat = np.array([x for v in latencies.values() for x in v])
    print(f"VSS under {len(sent)} random commands from {args.clients} WebSocket clients "
          f"(random 0-100 ms spacing, answers not awaited), lockstep ×{PACE:g} at most")
    print(f"  run: {wall:.1f} s wall, {mount_s:.0f} s mount time, "
          f"{telescope.supervisor.operations_started} operations started")
    print(f"  answers: {dict(outcomes.most_common())}")
    print(f"  orphaned operations (mount commands from a replaced one): {orphans}   (goal 0)")
    print(f"  operation tasks alive after the final stop: {len(live_ops)}   (goal 0)")
    print(f"  unanswered: {unanswered}, answered twice: {twice}   (goal 0, 0)")
    print(f"  motion after the final stop ({final['answer']['result']}): {len(after_stop)} "
          f"mount commands, encoders moved {math.degrees(moved) * 3600:.2f}″ over 60 s, "
          f"states {sorted(states)}   (goal 0 commands, still)")
    print(f"  answer latency (wall): p50 {np.percentile(lat, 50) * 1e3:.1f} ms, p99 "
          f"{np.percentile(lat, 99) * 1e3:.0f} ms (slews and waits included)")
    print(f"  reference: ping in the same run p50 {np.percentile(ping, 50) * 1e3:.2f} ms, p99 "
          f"{np.percentile(ping, 99) * 1e3:.2f} ms")
    assert last_op == telescope.supervisor.operations_started
    ok = (orphans == 0 and not live_ops and unanswered == 0 and twice == 0 and not after_stop
          and moved < STILL_RAD and states <= {"HOLDING", "OFF"})
    print("  goals met" if ok else "  GOALS NOT MET")


if __name__ == "__main__":
    main()
