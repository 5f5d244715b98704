"""Run inside a private network namespace: vs server + indiserver vs-indi + the INDI CLI tools.

Usage: indi_scenario.py RA_JNOW_H DEC_JNOW_DEG TLE_FILE; prints one JSON object of what it saw.
(indiserver listens on every interface, so it only ever runs inside `unshare -n`.)
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

BIN = Path(sys.executable).parent
HOST = ["-h", "127.0.0.1", "-p", "7624"]
D = "VirtualStar"


def get(prop: str) -> str:
    out = subprocess.run(["indi_getprop", *HOST, "-1", "-t", "10", f"{D}.{prop}"],
                         capture_output=True, text=True, timeout=30)
    return out.stdout.strip()


def put(assignment: str) -> None:
    subprocess.run(["indi_setprop", *HOST, "-t", "10", f"{D}.{assignment}"], check=True,
                   timeout=30)


def wait_state(prop: str, states: tuple[str, ...], timeout_s: float = 120.0) -> str:
    deadline = time.monotonic() + timeout_s
    while True:
        state = get(f"{prop}._STATE")
        if state in states or time.monotonic() > deadline:
            return state
        time.sleep(0.1)


class StateLog:
    """Every state a property announces, in order, as a Python INDI client (indipyclient) sees
    them: a Busy that lasts a moment is recorded even when a poll of indi_getprop misses it."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []
        self.lock = threading.Lock()
        self.client = None
        self.loop: asyncio.AbstractEventLoop | None = None
        threading.Thread(target=lambda: asyncio.run(self._run()), daemon=True).start()

    async def _run(self) -> None:
        from indipyclient import IPyClient

        log = self

        class Recorder(IPyClient):
            async def rxevent(self, event) -> None:
                state = getattr(event, "state", None)
                if event.devicename == D and event.vectorname and state:
                    with log.lock:
                        log.events.append((event.vectorname, state))

        self.client = Recorder(indihost="127.0.0.1", indiport=7624)
        self.loop = asyncio.get_running_loop()
        await self.client.asyncrun()

    def send(self, *vectors: tuple[str, dict[str, str]]) -> None:
        """Send new vectors back to back on this one connection (indiserver keeps a
        client's order), e.g. a goto and the abort right behind it."""
        async def both() -> None:
            for name, members in vectors:
                await self.client.send_newVector(D, name, members=members)

        assert self.loop is not None
        asyncio.run_coroutine_threadsafe(both(), self.loop).result(30)

    def mark(self) -> int:
        with self.lock:
            return len(self.events)

    def states(self, vector: str, since: int) -> list[str]:
        with self.lock:
            return [st for name, st in self.events[since:] if name == vector]

    def _until(self, vector: str, since: int, timeout_s: float, judge):
        """Poll `vector`'s states since the mark `since` until `judge` of them is not None;
        return that (None when the timeout ran out)."""
        deadline = time.monotonic() + timeout_s
        while (found := judge(self.states(vector, since))) is None:
            if time.monotonic() > deadline:
                return None
            time.sleep(0.02)
        return found

    def wait(self, vector: str, state: str, since: int, timeout_s: float = 120.0,
             after: str | None = None) -> bool:
        """True once `vector` has announced `state` after the mark `since` (and, with `after`,
        after its first announcement of that state: Ok after Busy, not a poll's Ok before)."""
        def seen(states: list[str]) -> bool | None:
            if after is not None:
                states = states[states.index(after) + 1:] if after in states else []
            return True if state in states else None

        return self._until(vector, since, timeout_s, seen) is True

    def answer(self, vector: str, since: int, timeout_s: float) -> str | None:
        """The answer to a command on `vector` sent after the mark `since`: Alert if refused
        at once, else the Alert or Ok that ends its Busy (None if none within the timeout).
        Leading Oks are the status poll repeating the state before the command."""
        def ended(states: list[str]) -> str | None:
            while states and states[0] == "Ok":
                states.pop(0)
            if states and states[0] == "Alert":
                return "Alert"
            return next((st for st in states[1:] if st in ("Alert", "Ok")), None)

        return self._until(vector, since, timeout_s, ended)

    def from_first(self, vector: str, state: str, since: int) -> list[str]:
        """The states announced after `since`, from the first `state` on."""
        states = self.states(vector, since)
        return states[states.index(state):] if state in states else states


def status() -> dict:
    out = subprocess.run([str(BIN / "vs"), "status", "--json"], capture_output=True, text=True,
                         timeout=60)
    return json.loads(out.stdout)


def phase() -> str:
    op = status()["operation"]
    return op["phase"] if op else "none"


async def python_client() -> dict:
    """The hand pad and a satellite through a Python INDI client (indipyclient)."""
    from indipyclient import IPyClient

    client = IPyClient(indihost="127.0.0.1", indiport=7624)
    running = asyncio.create_task(client.asyncrun())
    out: dict = {}

    async def until(check, timeout_s: float = 60.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                if check():
                    return True
            except KeyError:
                pass
            await asyncio.sleep(0.05)
        return False

    def vector(name):
        return client[D][name]

    from virtualstar.vss_client import VssClient

    vss = await VssClient.connect("ws://127.0.0.1:8740")

    async def now() -> dict:
        return await vss.request("status")

    async def rate_after(axis: str, since_us: int) -> float:
        """An axis rate (deg/s) measured over 5 mount seconds, 15 mount seconds after since_us
        (past the stop, the lead and the run-up however fast the host runs)."""
        a = await now()
        while a["mount_time_us"] < since_us + 15_000_000:
            await asyncio.sleep(0.02)
            a = await now()
        b = await now()
        while b["mount_time_us"] < a["mount_time_us"] + 5_000_000:
            await asyncio.sleep(0.02)
            b = await now()
        return ((b["encoder"][axis] - a["encoder"][axis])
                / ((b["mount_time_us"] - a["mount_time_us"]) / 1e6))

    try:
        await until(lambda: "SAT_TRACKING_STAT" in client[D])
        # from a known place, so that no limit is near while the hand pad runs
        await client.send_newVector(D, "HORIZONTAL_COORD", members={"AZ": "180", "ALT": "30"})
        await until(lambda: vector("HORIZONTAL_COORD").state == "Busy", 30)
        await until(lambda: vector("HORIZONTAL_COORD").state == "Ok", 120)
        since = (await now())["mount_time_us"]
        await client.send_newVector(D, "TELESCOPE_MOTION_WE", members={"MOTION_EAST": "On"})
        out["motion_busy"] = await until(lambda: vector("TELESCOPE_MOTION_WE").state == "Busy")
        out["motion_az_rate_deg_s"] = await rate_after("az_deg", since)
        since = (await now())["mount_time_us"]
        await client.send_newVector(D, "TELESCOPE_MOTION_NS", members={"MOTION_NORTH": "On"})
        out["motion_el_rate_deg_s"] = await rate_after("el_deg", since)
        await client.send_newVector(D, "TELESCOPE_MOTION_WE", members={"MOTION_EAST": "Off"})
        await client.send_newVector(D, "TELESCOPE_MOTION_NS", members={"MOTION_NORTH": "Off"})
        out["motion_idle"] = await until(lambda: vector("TELESCOPE_MOTION_WE").state == "Idle"
                                         and vector("TELESCOPE_MOTION_NS").state == "Idle")
        tle = Path(sys.argv[3]).read_text()
        await client.send_newVector(D, "SAT_TLE_TEXT", members={"TLE": tle})
        # a window (as KStars writes it) in which the satellite has no pass: refused
        await client.send_newVector(D, "SAT_PASS_WINDOW", members={
            "SAT_PASS_WINDOW_START": "2024-05-18T21:02:00", "SAT_PASS_WINDOW_END":
            "2024-05-18T21:03:00"})
        await client.send_newVector(D, "SAT_TRACKING_STAT", members={"SAT_TRACK": "On",
                                                                     "SAT_HALT": "Off"})
        out["sat_window_refused"] = await until(
            lambda: vector("SAT_TRACKING_STAT").state == "Alert", 30)
        # no window: the server chooses the pass and says which
        await client.send_newVector(D, "SAT_PASS_WINDOW", members={
            "SAT_PASS_WINDOW_START": "", "SAT_PASS_WINDOW_END": ""})
        await client.send_newVector(D, "SAT_TRACKING_STAT", members={"SAT_TRACK": "On",
                                                                     "SAT_HALT": "Off"})
        out["sat_busy"] = await until(lambda: vector("SAT_TRACKING_STAT").state == "Busy")
        await until(lambda: vector("SAT_PASS_WINDOW")["SAT_PASS_WINDOW_START"] != "")
        out["sat_window"] = [vector("SAT_PASS_WINDOW")["SAT_PASS_WINDOW_START"],
                             vector("SAT_PASS_WINDOW")["SAT_PASS_WINDOW_END"]]
        out["sat_operation"] = status()["operation"]["kind"]
        await client.send_newVector(D, "TELESCOPE_ABORT_MOTION", members={"ABORT": "On"})
        out["sat_after_abort"] = await until(
            lambda: vector("SAT_TRACKING_STAT").state == "Alert", 30)
    finally:
        await vss.close()
        client.shutdown()
        await asyncio.wait_for(running, 30)
    return out


def main() -> None:
    ra_h, dec = sys.argv[1], sys.argv[2]
    env = dict(os.environ, VS_SERVER="ws://127.0.0.1:8740", PATH=f"{BIN}:{os.environ['PATH']}")
    os.environ.update(env)
    vss = subprocess.Popen([str(BIN / "vs"), "server", "--emulator", "--speed", "20", "--start",
                            "2024-05-18T21:00:00Z"], stdout=subprocess.PIPE, text=True, env=env)
    vss.stdout.readline()  # "VirtualStar Server on ws://...": listening
    indi = subprocess.Popen(["indiserver", "-p", "7624", str(BIN / "vs-indi")], env=env,
                            stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    seen: dict = {}
    try:
        deadline = time.monotonic() + 60
        while not get("CONNECTION.CONNECT") and time.monotonic() < deadline:
            time.sleep(0.2)
        seen["connect_before"] = get("CONNECTION.CONNECT")
        log = StateLog()
        time.sleep(0.5)
        put("CONNECTION.CONNECT=On")
        seen["connection_state"] = wait_state("CONNECTION", ("Ok", "Alert"), 30)
        time.sleep(1.5)  # one status poll
        seen["lat"] = float(get("GEOGRAPHIC_COORD.LAT"))
        seen["utc"] = get("TIME_UTC.UTC")
        listing = subprocess.run(["indi_getprop", *HOST, "-1", "-t", "10", f"{D}.ON_COORD_SET.*"],
                                 capture_output=True, text=True, timeout=30).stdout
        seen["coord_set_members"] = sorted(line.split(".")[2].split("=")[0]
                                           for line in listing.split())
        # no switch On in a OneOfMany vector: refused (libindi's rule), the driver lives on
        put("ON_COORD_SET.TRACK=Off")
        seen["one_of_many_state"] = wait_state("ON_COORD_SET", ("Alert",), 30)
        seen["coord_set_track"] = get("ON_COORD_SET.TRACK")
        # the client's location: the server's is Ok, another is Alert
        put(f"GEOGRAPHIC_COORD.LAT;LONG={seen['lat']};{float(get('GEOGRAPHIC_COORD.LONG'))}")
        seen["geo_same"] = wait_state("GEOGRAPHIC_COORD", ("Ok", "Alert"), 30)
        put("GEOGRAPHIC_COORD.LAT;LONG=-33.9;18.4")
        seen["geo_other"] = wait_state("GEOGRAPHIC_COORD", ("Alert",), 30)
        # an impossible declination: Alert, and the driver keeps answering
        put("EQUATORIAL_EOD_COORD.RA;DEC=1;100")
        # (indi_setprop returns once sent: the driver's answer is awaited, never assumed)
        seen["bad_state"] = wait_state("EQUATORIAL_EOD_COORD", ("Alert",), 30)
        # slew and track a JNow place: Busy at once, Ok only when the VSS says it landed
        mark = log.mark()
        put(f"EQUATORIAL_EOD_COORD.RA;DEC={ra_h};{dec}")
        log.wait("EQUATORIAL_EOD_COORD", "Busy", mark, 30)
        states = [get("EQUATORIAL_EOD_COORD._STATE")]
        op_phases = [phase()]
        while states[-1] == "Busy":
            time.sleep(0.1)
            op_phases.append(phase())
            states.append(get("EQUATORIAL_EOD_COORD._STATE"))
        seen["slew_states"] = states
        seen["slew_phases"] = op_phases
        log.wait("EQUATORIAL_EOD_COORD", "Ok", mark, 60, after="Busy")
        seen["slew_announced"] = log.from_first("EQUATORIAL_EOD_COORD", "Busy", mark)
        st = status()
        seen["after_slew"] = {"t_us": st["mount_time_us"], "observed": st["observed"],
                              "phase": st["operation"]["phase"]}
        time.sleep(1.5)
        seen["eod"] = [float(get("EQUATORIAL_EOD_COORD.RA")), float(get("EQUATORIAL_EOD_COORD.DEC"))]
        seen["track_state"] = get("TELESCOPE_TRACK_STATE.TRACK_ON")
        # a guide pulse north: Busy, then Ok
        mark = log.mark()
        put("TELESCOPE_TIMED_GUIDE_NS.TIMED_GUIDE_N;TIMED_GUIDE_S=2000;0")
        log.wait("TELESCOPE_TIMED_GUIDE_NS", "Ok", mark, 60, after="Busy")
        seen["guide_states"] = log.from_first("TELESCOPE_TIMED_GUIDE_NS", "Busy", mark)
        # an offset through VirtualStar's VS_OFFSET vector: sets the dec total on the track
        put("VS_OFFSET.DEC=12")
        seen["offset_state"] = wait_state("VS_OFFSET", ("Ok", "Alert"), 30)
        time.sleep(2.5)  # the offset has run; two status polls
        seen["offset_dec"] = float(get("VS_OFFSET.DEC"))
        seen["offset_status"] = status()["corrections"]["offsets"]["axes"]["dec"]["total_arcsec"]
        put("VS_OFFSET.PATH=900")  # beyond the vector's range: refused whole
        seen["offset_beyond"] = wait_state("VS_OFFSET", ("Alert",), 30)
        put("VS_OFFSET_RESET.RESET=On")
        seen["offset_reset_state"] = wait_state("VS_OFFSET_RESET", ("Ok", "Alert"), 30)
        time.sleep(2.5)
        seen["offset_after_reset"] = float(get("VS_OFFSET.DEC"))
        # a second goto right behind the first (one connection, so the first is still Busy
        # however loaded the host): the first's end is not reported as Alert
        mark = log.mark()
        log.send(("HORIZONTAL_COORD", {"AZ": "200", "ALT": "40"}),
                 ("HORIZONTAL_COORD", {"AZ": "210", "ALT": "45"}))
        log.wait("HORIZONTAL_COORD", "Ok", mark, 120, after="Busy")
        seen["second_goto_states"] = log.from_first("HORIZONTAL_COORD", "Busy", mark)
        time.sleep(1.5)  # a status poll after the landing
        seen["second_goto_az"] = float(get("HORIZONTAL_COORD.AZ"))
        # ON_COORD_SET SLEW: go there and stay (tracking off afterwards)
        put("ON_COORD_SET.SLEW=On")
        mark = log.mark()
        put(f"EQUATORIAL_EOD_COORD.RA;DEC={ra_h};{dec}")
        log.wait("EQUATORIAL_EOD_COORD", "Ok", mark, 120, after="Busy")
        seen["slew_mode_end"] = get("EQUATORIAL_EOD_COORD._STATE")
        time.sleep(1.5)  # a status poll
        seen["slew_mode_tracking"] = get("TELESCOPE_TRACK_STATE.TRACK_ON")
        put("ON_COORD_SET.TRACK=On")
        # a long goto and an abort right behind it: whether the goto reached the VSS or was
        # still in the driver, it never lands; Alert on the coordinates, the mount at rest
        mark = log.mark()
        before_op = (status()["operation"] or {}).get("id")
        log.send(("HORIZONTAL_COORD", {"AZ": "300", "ALT": "30"}),
                 ("TELESCOPE_ABORT_MOTION", {"ABORT": "On"}))
        log.wait("TELESCOPE_ABORT_MOTION", "Ok", mark, 30)
        # the goto's own answer from the state log (a poll of the property could still show
        # the Ok of the step before, if the driver had not yet dropped the goto)
        seen["abort_state"] = log.answer("HORIZONTAL_COORD", mark, 60)
        st = status()
        seen["after_abort"] = {"op": st["operation"], "before_op": before_op,
                               "t_us": st["mount_time_us"], "observed": st["observed"]}
        st = status()
        while st["mount_time_us"] < seen["after_abort"]["t_us"] + 10_000_000:  # however slow
            time.sleep(0.1)
            st = status()
        seen["after_abort_later"] = {"t_us": st["mount_time_us"], "observed": st["observed"]}
        seen.update(asyncio.run(python_client()))
        # park; indi_eval waits for the state Ok (1)
        mark = log.mark()
        put("TELESCOPE_PARK.PARK;UNPARK=On;Off")
        subprocess.run(["indi_eval", *HOST, "-w", "-t", "120",
                        f'"{D}.TELESCOPE_PARK._STATE"==1'], timeout=150)
        seen["park_states"] = log.from_first("TELESCOPE_PARK", "Busy", mark)
        seen["park_end"] = get("TELESCOPE_PARK._STATE")
        seen["parked"] = get("TELESCOPE_PARK.PARK")
        put("HORIZONTAL_COORD.AZ;ALT=100;40")
        seen["goto_while_parked"] = wait_state("HORIZONTAL_COORD", ("Alert",), 30)
        put("TELESCOPE_PARK.PARK;UNPARK=Off;On")
        wait_state("TELESCOPE_PARK", ("Ok",), 30)
        time.sleep(2.5)  # two status polls: UNPARK sticks
        seen["unparked"] = get("TELESCOPE_PARK.UNPARK")
        put("HORIZONTAL_COORD.AZ;ALT=100;40")
        wait_state("HORIZONTAL_COORD", ("Busy",), 30)
        seen["goto_after_unpark"] = wait_state("HORIZONTAL_COORD", ("Ok", "Alert"), 120)
        seen["vss_alive"] = vss.poll() is None and indi.poll() is None
    finally:
        indi.terminate()
        vss.terminate()
        indi.wait(30)
        vss.wait(30)
    print(json.dumps(seen))


if __name__ == "__main__":
    main()
