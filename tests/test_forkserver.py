"""The session's fork server (tests/forkserver.py) runs what subprocess.Popen would have run.

Each test runs the same program both ways and compares what the child saw and did: the
fresh interpreter is the truth.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import forkserver
import pytest

# What a child reports of itself: its arguments, environment, directory, import path, standard
# streams, signal handlers and main module; then it exits with the status it was given.
PROBE = """
import json, os, signal, sys, threading
print(json.dumps({
    "argv": sys.argv, "orig_argv": sys.orig_argv, "marker": os.environ.get("FORKSERVER_PROBE"), "cwd": os.getcwd(),
    "path0": sys.path[0], "stdin": sys.stdin.read(), "name": __name__,
    "stdout_line_buffering": sys.stdout.line_buffering,
    "stdout_write_through": sys.stdout.write_through,
    "stderr_line_buffering": sys.stderr.line_buffering,
    "sigint": signal.getsignal(signal.SIGINT) is signal.default_int_handler,
    "sigterm": signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
    "threads": threading.active_count(),
}))
print("to stderr", file=sys.stderr)
sys.exit(int(sys.argv[1]))
"""


@pytest.fixture(scope="module")
def server_path() -> str:
    path = os.environ.get(forkserver.SOCKET_ENV_VAR)
    if path == "off":
        pytest.skip(f"{forkserver.SOCKET_ENV_VAR}=off: this session runs without a fork server")
    if not path:
        pytest.fail("tests/conftest.py did not start the session's fork server")
    if not forkserver.wait_serving(path, 120):  # it imports as the session starts
        pytest.fail(f"the fork server never served at {path}")
    return path


def _both(args: list[str], **kwargs) -> tuple[subprocess.Popen, subprocess.Popen]:
    return forkserver.popen(args, **kwargs), subprocess.Popen(args, **kwargs)


@pytest.mark.parametrize(("unbuffered", "options"), [({}, []), ({"PYTHONUNBUFFERED": "1"}, []),
                                                     ({}, ["-u"])])  # -u: xdist's workers
def test_a_forked_child_sees_and_does_what_a_fresh_interpreter_would(server_path, tmp_path,
                                                                     unbuffered, options):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    env.update({"FORKSERVER_PROBE": "zeta ✓", **unbuffered})
    results = []
    procs = _both([sys.executable, *options, "-c", PROBE, "7", "two words"],
                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                  text=True, env=env, cwd=tmp_path)
    assert isinstance(procs[0], forkserver.ForkedPopen)
    for proc in procs:
        out, err = proc.communicate("piped in", timeout=60)
        results.append((json.loads(out), err, proc.returncode))
    forked, fresh = results
    assert forked == fresh
    assert forked[0]["argv"] == ["-c", "7", "two words"] and forked[2] == 7
    assert forked[0]["orig_argv"][1:len(options) + 1] == options
    assert forked[0]["stdout_write_through"] == bool(unbuffered or options)
    assert forked[0]["threads"] == 1


def test_popen_forks_only_when_the_fork_server_serves_that_environment(server_path):
    args = [sys.executable, "-c", "pass"]
    forked = forkserver.popen(args)
    assert isinstance(forked, forkserver.ForkedPopen)
    # a variable Python reads as it starts: a fork would not honour it
    fresh = forkserver.popen(args, env={**os.environ, "PYTHONHASHSEED": "123"})
    # and options a fork cannot honour
    own_session = forkserver.popen(args, start_new_session=True)
    assert not isinstance(fresh, forkserver.ForkedPopen)
    assert not isinstance(own_session, forkserver.ForkedPopen)
    assert [p.wait(60) for p in (forked, fresh, own_session)] == [0, 0, 0]


def test_a_console_script_runs_forked_as_it_runs_fresh(server_path):
    vs = str(Path(sys.executable).with_name("vs"))
    outs = []
    for proc in _both([vs, "where", "--help"], stdout=subprocess.PIPE, text=True,
                      env={**os.environ, "COLUMNS": "100"}):
        outs.append((proc.communicate(timeout=60)[0], proc.returncode))
    assert outs[0] == outs[1] and outs[0][1] == 0 and "Usage: vs where" in outs[0][0]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL, signal.SIGINT])
def test_a_signal_ends_a_forked_child_as_it_ends_a_fresh_one(server_path, sig):
    # the child says it is ready, then sleeps; SIGINT raises KeyboardInterrupt in it
    code = "import sys, time\nprint('ready', flush=True)\ntime.sleep(60)"
    results = []
    for proc in _both([sys.executable, "-c", code], stdout=subprocess.PIPE,
                      stderr=subprocess.PIPE, text=True):
        assert proc.stdout.readline() == "ready\n"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        results.append((proc.returncode, err.strip().splitlines()[-1:] if err else []))
    assert results[0] == results[1]
    assert results[0][0] == -sig  # (Python ends itself with SIGINT after a KeyboardInterrupt)


def test_waiting_for_a_forked_child_times_out_and_the_child_can_be_killed(server_path):
    proc = forkserver.popen([sys.executable, "-c", "import time; time.sleep(60)"])
    assert isinstance(proc, forkserver.ForkedPopen)
    with pytest.raises(subprocess.TimeoutExpired):
        proc.wait(timeout=0.2)
    assert proc.poll() is None
    proc.kill()
    assert proc.wait(timeout=60) == -signal.SIGKILL
    proc.send_signal(signal.SIGTERM)  # after the child is gone: nothing happens, no error
    assert proc.poll() == -signal.SIGKILL


def test_a_forked_childs_cpu_is_counted_once_it_is_waited_for_as_a_reaped_childs_is(server_path):
    burn = ("import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3:\n"
            "    pass")
    forked = forkserver.popen([sys.executable, "-c", burn])
    assert isinstance(forked, forkserver.ForkedPopen)
    before = forkserver.reaped_cpu_s
    assert forked.wait(timeout=60) == 0
    burned_s = forkserver.reaped_cpu_s - before
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    fresh = subprocess.Popen([sys.executable, "-c", burn])
    assert fresh.wait(timeout=60) == 0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    fresh_s = (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime)
    # both count the loop's 0.3 s, and a little more: a fresh interpreter's start-up, a forked
    # one's teardown of the modules it inherited
    assert 0.3 <= fresh_s < 1.3 and 0.3 <= burned_s < fresh_s + 1.0, (burned_s, fresh_s)


@pytest.mark.parametrize("request_bytes", [
    b"", b"\x00\x00\x00\x05junk!", b'\x00\x00\x00\x02[]',
    b'\x00\x00\x00\x3a{"argv": ["/bin/sh", "-c", "true"], "env": {}, "cwd": "/"}',
])
def test_a_request_the_fork_server_cannot_use_is_closed_and_it_goes_on_serving(server_path,
                                                                                request_bytes):
    import socket

    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
        conn.settimeout(60)
        conn.connect(server_path)
        if request_bytes:  # (else: a client that connects and says nothing)
            socket.send_fds(conn, [request_bytes], [0, 1, 2])
        conn.shutdown(socket.SHUT_WR)
        assert conn.recv(100) == b""  # closed, no pid
    proc = forkserver.popen([sys.executable, "-c", "pass"])
    assert isinstance(proc, forkserver.ForkedPopen)
    assert proc.wait(timeout=60) == 0


def test_the_xdist_workers_are_forks_of_the_fork_server(server_path):
    # tests/conftest.py starts pytest-xdist's workers through forkserver.popen
    if "PYTEST_XDIST_WORKER" not in os.environ:
        pytest.skip("not run by a pytest-xdist worker (make test runs them)")
    parent = Path(f"/proc/{os.getppid()}/cmdline").read_bytes().split(b"\0")
    assert any(arg.endswith(b"forkserver.py") for arg in parent), parent
    assert sys.orig_argv[1:3] == ["-u", "-c"]  # as execnet starts a worker
