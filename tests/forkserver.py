"""Start the suite's workers and its `vs`, emulator and device processes as forks of one
pre-imported Python.

A `vs server --emulator` spends 1.1–1.6 s of CPU importing the server, the astronomy and the
emulator before it serves, and the suite starts about twenty of them (benchmarks/bench_suite.py
--processes). The session's fork server (started by tests/conftest.py, one per session) has
imported them once (and what the pytest-xdist workers import as they start and collect:
tests/conftest.py starts the workers through it too); `popen(args, ...)` asks it to fork a
child that runs exactly what `subprocess.Popen(args, ...)` would have run: the same
`python [-u] -c CODE`, `python [-u] -m MODULE` or console script with the same arguments,
environment, working directory and pipes, from a fresh `__main__`, with the default signal
handlers, and exiting as that process would (atexit, its exit status, death by a signal).
What differs is only that the modules were imported (and numba's registries and astropy's
IERS-A table loaded) before the child existed.

`popen` falls back to `subprocess.Popen` (a fresh interpreter) whenever that could differ:
no fork server in this session, options a fork cannot honour (a new session or process
group, `preexec_fn`, `pass_fds`, another user), a command that is not Python, or an
environment that differs from the server's in a variable read while importing (PYTHON*,
NUMBA_*, OPENBLAS_*, locale, HOME, XDG_* ...: FORK_SENSITIVE). Tests of how a command starts
(tests/vss/test_vss_demo_and_server.py) use `subprocess.Popen` itself.

The child's pid is its own; the test signals and waits for it through a pidfd, so that a pid
the server has reaped is never signalled. The server reaps a child only when its test asks
for the exit status (or has gone away), and answers with the CPU the child used, which
`reaped_cpu_s` adds up as the kernel adds up a process's reaped children.

The socket lies in the session's private cache directory (tempfile.mkdtemp: mode 0700), so
only the user running the tests can ask it for anything; a request that is not a well-formed
Python command of this environment is closed unanswered, and the server goes on serving.

    python tests/forkserver.py SOCKET_PATH     (tests/conftest.py starts it)
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time

SOCKET_ENV_VAR = "VIRTUALSTAR_TEST_FORKSERVER"
# Environment variables that Python or a library imported by the fork server reads while
# starting or importing: a request whose value differs runs in a fresh interpreter instead.
FORK_SENSITIVE_PREFIXES = ("PYTHON", "NUMBA_", "OPENBLAS_", "OMP_", "MKL_", "NUMPY_", "ASTROPY_",
                           "MPL", "XDG_", "LD_", "MALLOC_", "LC_")
FORK_SENSITIVE = {"HOME", "LANG", "LANGUAGE", "TZ", "VIRTUALSTAR_CACHE_DIR"}
RUNTIME_ONLY = {"PYTHONUNBUFFERED", "PYTHONFAULTHANDLER"}  # the child applies them itself
HONOURED_OPTIONS = {"-u"}  # interpreter options the child applies itself (unbuffered streams)
_MAX_REQUEST = 1 << 20
# The CPU of this process's forked children that have been waited for (with the children they
# waited for): what getrusage(RUSAGE_CHILDREN) would have counted had this process started
# them itself (benchmarks/suite_cpu_plugin.py adds it).
reaped_cpu_s = 0.0


# -- the client side (a pytest worker) ----------------------------------------------------------

def _fork_sensitive(env: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if k not in RUNTIME_ONLY
            and (k in FORK_SENSITIVE or k.startswith(FORK_SENSITIVE_PREFIXES))}


def _python_command(args: list[str]) -> bool:
    """True for `python [-u] -c CODE ...`, `python [-u] -m MODULE ...` and this environment's
    console scripts (vs, mount-emulator, astcom ...), which are Python files in the
    interpreter's folder."""
    if not args:
        return False
    first = os.fspath(args[0])
    if first == sys.executable:
        _, rest = _options(args)
        return len(rest) >= 3 and rest[1] in ("-c", "-m")
    bindir = os.path.dirname(sys.executable)
    if os.path.dirname(first) != bindir or not os.path.isfile(first):
        return False
    with open(first, "rb") as f:
        return f.readline().rstrip() == b"#!" + os.fsencode(sys.executable)


def _options(args: list[str]) -> tuple[list[str], list[str]]:
    """Split `python [OPTIONS] ...` into the options a fork honours (-u, as pytest-xdist starts
    its workers) and the interpreter followed by the rest; a console script has none."""
    if os.fspath(args[0]) != sys.executable:
        return [], list(args)
    k = 1
    while k < len(args) and args[k] in HONOURED_OPTIONS:
        k += 1
    return list(args[1:k]), [args[0], *args[k:]]


class ForkedPopen(subprocess.Popen):
    """A `subprocess.Popen` whose child the fork server forked (see the module docstring)."""

    def __init__(self, args, *, server_path: str, **kwargs) -> None:
        self._server_path = server_path
        self._conn: socket.socket | None = None
        self._pidfd = -1
        self._status_lock = threading.Lock()
        super().__init__(args, **kwargs)

    # Popen calls this where it would fork and exec; the arguments are those of CPython
    # 3.11's POSIX implementation, and popen() only passes what a fork honours.
    def _execute_child(self, args, executable, preexec_fn, close_fds, pass_fds, cwd, env,
                       startupinfo, creationflags, shell, p2cread, p2cwrite, c2pread, c2pwrite,
                       errread, errwrite, restore_signals, gid, gids, uid, umask,
                       start_new_session, process_group) -> None:
        fds = [p2cread if p2cread != -1 else 0, c2pwrite if c2pwrite != -1 else 1,
               errwrite if errwrite != -1 else 2]
        request = json.dumps({"argv": [os.fspath(a) for a in args],
                              "env": dict(os.environ if env is None else env),
                              "cwd": os.fspath(cwd) if cwd is not None else os.getcwd()}).encode()
        conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            conn.connect(self._server_path)
            socket.send_fds(conn, [len(request).to_bytes(4, "big") + request], fds)
            reply = json.loads(_read_line(conn))
            self.pid = reply["pid"]
            self._pidfd = os.pidfd_open(self.pid)  # the server has not reaped it: still valid
        except BaseException:
            conn.close()
            raise
        self._conn = conn
        self._child_created = True
        self._close_pipe_fds(p2cread, p2cwrite, c2pread, c2pwrite, errread, errwrite)

    def _collect_status(self) -> None:
        """Ask the server for the exit status of the child, which has exited."""
        with self._status_lock:
            if self.returncode is not None or self._conn is None:
                return
            try:
                self._conn.sendall(b"wait\n")
                reply = json.loads(_read_line(self._conn))
                global reaped_cpu_s
                reaped_cpu_s += reply["cpu_s"]
                self._handle_exitstatus(reply["status"])
            finally:
                self._conn.close()
                self._conn = None
                os.close(self._pidfd)
                self._pidfd = -1

    def _internal_poll(self, _deadstate=None, **_unused):
        if (self.returncode is None and self._pidfd >= 0
                and select.select([self._pidfd], [], [], 0)[0]):
            self._collect_status()
        return self.returncode

    def _wait(self, timeout):
        if self.returncode is not None or self._pidfd < 0:
            return self.returncode
        if not select.select([self._pidfd], [], [], timeout)[0]:
            raise subprocess.TimeoutExpired(self.args, timeout)
        self._collect_status()
        return self.returncode

    def send_signal(self, sig: int) -> None:
        self.poll()
        if self.returncode is None and self._pidfd >= 0:
            signal.pidfd_send_signal(self._pidfd, sig)


def _read_line(conn: socket.socket) -> bytes:
    data = b""
    while not data.endswith(b"\n"):
        part = conn.recv(4096)
        if not part:
            raise ConnectionError("the fork server closed the connection")
        data += part
    return data


def wait_serving(path: str, timeout_s: float, server: subprocess.Popen | None = None) -> bool:
    """Wait until the fork server at `path` serves (it imports for a second or more as the
    session starts); False if it has not after `timeout_s`, or if `server` has exited."""
    deadline = time.monotonic() + timeout_s
    while not os.path.exists(path):
        if time.monotonic() > deadline or (server is not None and server.poll() is not None):
            return False
        time.sleep(0.02)
    return True


def popen(args: list, **kwargs) -> subprocess.Popen:
    """`subprocess.Popen(args, **kwargs)`, forked from the session's fork server when that
    runs exactly the same program (the module docstring says when it does not)."""
    path = os.environ.get(SOCKET_ENV_VAR)
    unsupported = {"preexec_fn", "pass_fds", "start_new_session", "process_group", "user",
                   "group", "extra_groups", "umask", "executable", "shell"}
    env = kwargs.get("env")
    if (not path or not os.path.exists(path) or any(kwargs.get(k) for k in unsupported)
            or not _python_command(list(args))
            or _fork_sensitive(os.environ if env is None else env) != _server_env(path)):
        return subprocess.Popen(args, **kwargs)
    try:
        return ForkedPopen(args, server_path=path, **kwargs)
    except (ConnectionError, FileNotFoundError):
        return subprocess.Popen(args, **kwargs)  # the server has gone (the session ends)


@functools.cache
def _server_env(path: str) -> dict[str, str]:
    """The fork-sensitive environment the server at `path` imported in (it writes it there
    before it serves)."""
    with open(path + ".env") as f:
        return json.load(f)


# -- the server side ----------------------------------------------------------------------------

PRE_IMPORTED = ("virtualstar.cli.main", "virtualstar.cli.server", "virtualstar.cli.status",
                "virtualstar.server.server", "virtualstar.launcher", "virtualstar.astro",
                "mount_emulator.emulator", "mount_emulator.cli", "astcom_client.example_device",
                "astcom_client.cli",
                "typer._adapters")  # (typer imports that one when it parses a command line)
# ... and what the pytest-xdist workers import as they start and collect, which they would
# otherwise each import again (~2 s of CPU apiece): pytest, and the libraries the test modules
# import at their top. Not pytest's plugins (xdist, pytest-timeout, anyio, hypothesis): pytest
# rewrites their asserts as it loads them, which it cannot do to a module imported before it
# started. Not pyarrow, pandas, polars or duckdb: importing them starts threads (the recorder's
# tests import them where they need them).
FOR_WORKERS = ("pytest", "execnet", "astropy.coordinates", "astropy.table", "astropy.io.ascii",
               "astropy.utils.iers", "scipy.optimize", "scipy.interpolate", "skyfield.api",
               "alpaca.telescope", "aiohttp", "pointing_model.cli", "virtualstar.alpaca.server",
               "virtualstar.indi.driver", "virtualstar.planning.planner", "virtualstar.anomalies",
               "virtualstar.panel.server", "guide_camera.device")


def _load_once() -> None:
    """What each child would otherwise do the first time it needs it: load numba's typing and
    lowering registries (as the first compiled function called or loaded from numba's cache
    does: 0.2 s of CPU in every emulator), and read astropy's bundled IERS-A table (as the
    first transformation that needs the Earth's orientation does: 0.4 s in most workers),
    offline as the tests read it (tests/conftest.py)."""
    from astropy.utils import iers
    from numba.core.registry import cpu_target

    cpu_target.target_context.refresh()
    cpu_target.typing_context.refresh()
    with iers.conf.set_temp("auto_download", False):
        iers.IERS_Auto.open()


def _serve(path: str) -> dict:
    """Import, then fork a child per request; return the request in the child."""
    import gc
    import importlib

    # import as `python -c` would, not from this script's folder: tests/guide_camera would
    # otherwise shadow the guide_camera package (as a namespace package) in every child
    sys.path[0] = ""
    for name in (*PRE_IMPORTED, *FOR_WORKERS):
        importlib.import_module(name)
    _load_once()
    if len(os.listdir("/proc/self/task")) != 1:
        # a thread would not exist in a forked child, and one holding a lock would freeze it
        sys.exit("fork server: an import started a thread; not serving (tests start fresh "
                 "interpreters)")
    gc.collect()
    gc.freeze()  # the children's collections leave the shared pages unwritten
    with open(path + ".env.tmp", "w") as f:
        json.dump(_fork_sensitive(dict(os.environ)), f)
    os.rename(path + ".env.tmp", path + ".env")
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path + ".tmp")
    listener.listen(64)
    os.rename(path + ".tmp", path)  # clients find it only when it serves
    children: dict[socket.socket, int] = {}  # a test's connection → its child
    orphans: list[int] = []  # children whose test went away: reaped when they exit
    session = os.getppid()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C ends the session, which ends this
    while os.getppid() == session:
        readable, _, _ = select.select([listener, *children], [], [], 1.0)
        orphans = [pid for pid in orphans if os.waitpid(pid, os.WNOHANG)[0] == 0]
        for sock in readable:
            if sock is listener:
                conn, _ = listener.accept()
                conn.settimeout(10.0)  # a test that connected and said nothing
                request = _receive_request(conn)
                if request is None:
                    conn.close()
                    continue
                pid = os.fork()
                if pid == 0:
                    listener.close()
                    for other in children:
                        other.close()
                    conn.close()
                    return request
                for fd in request["fds"]:
                    os.close(fd)
                children[conn] = pid
                with contextlib.suppress(OSError):  # a test gone already: its EOF says so
                    conn.sendall(json.dumps({"pid": pid}).encode() + b"\n")
            else:
                pid = children.pop(sock)
                try:
                    asked = sock.recv(16).startswith(b"wait")
                except OSError:
                    asked = False
                if asked:
                    _, status, use = os.wait4(pid, 0)
                    reply = {"status": status, "cpu_s": use.ru_utime + use.ru_stime}
                    with contextlib.suppress(OSError):  # the test went away meanwhile
                        sock.sendall(json.dumps(reply).encode() + b"\n")
                else:
                    orphans.append(pid)
                sock.close()
    sys.exit(0)  # the session is gone


def _receive_request(conn: socket.socket) -> dict | None:
    try:
        data, fds, _, _ = socket.recv_fds(conn, _MAX_REQUEST + 4, 3)
        size = int.from_bytes(data[:4], "big")
        while len(data) < size + 4:
            part = conn.recv(size + 4 - len(data))
            if not part:
                raise ConnectionError
            data += part
        request = json.loads(data[4:])
    except (OSError, ValueError):
        request = None
    if len(fds) != 3 or not _well_formed(request):
        for fd in fds:
            os.close(fd)
        return None
    request["fds"] = fds
    return request


def _well_formed(request) -> bool:
    """A request names a Python command of this environment (as popen checks), its
    environment and its working directory, all as text."""
    return (isinstance(request, dict) and isinstance(request.get("argv"), list)
            and all(isinstance(a, str) for a in request["argv"])
            and isinstance(request.get("env"), dict)
            and all(isinstance(k, str) and isinstance(v, str)
                    for k, v in request["env"].items())
            and isinstance(request.get("cwd"), str) and _python_command(request["argv"]))


def _become(request: dict) -> None:
    """In the child: the standard streams, directory, environment, signals and argv of the
    process the test asked for."""
    import io

    for target, fd in enumerate(request["fds"]):
        os.dup2(fd, target)
    for fd in set(request["fds"]) - {0, 1, 2}:
        os.close(fd)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD, signal.SIGALRM):
        signal.signal(sig, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    options, _ = _options(request["argv"])
    unbuffered = bool(os.environ.get("PYTHONUNBUFFERED")) or "-u" in options

    def stream(fd: int, mode: str, errors: str) -> io.TextIOWrapper:
        raw = io.FileIO(fd, mode, closefd=False)
        if unbuffered and mode == "w":
            binary = raw
        else:
            binary = io.BufferedReader(raw) if mode == "r" else io.BufferedWriter(raw)
        return io.TextIOWrapper(binary, encoding="utf-8", errors=errors,
                                line_buffering=(mode == "w" and not unbuffered
                                                and (fd == 2 or raw.isatty())),
                                write_through=unbuffered and mode == "w")

    sys.stdin = sys.__stdin__ = stream(0, "r", "strict")
    sys.stdout = sys.__stdout__ = stream(1, "w", "strict")
    sys.stderr = sys.__stderr__ = stream(2, "w", "backslashreplace")
    if os.environ.get("PYTHONFAULTHANDLER"):
        import faulthandler

        faulthandler.enable()
    if "numpy" in sys.modules:  # a fresh process seeds numpy's global generator afresh
        sys.modules["numpy"].random.seed()


def _run(argv: list[str]) -> None:
    """Run `argv` as `python ARGV[1:]` or the console script ARGV[0] would."""
    import runpy

    sys.orig_argv = list(argv)  # as the interpreter the test asked for would hold it
    _, argv = _options(argv)  # (_become applied them)
    if argv[0] == sys.executable and argv[1] == "-c":
        sys.argv = ["-c", *argv[3:]]
        sys.path[0] = ""
        main = type(sys)("__main__")
        main.__dict__["__builtins__"] = __builtins__
        sys.modules["__main__"] = main
        exec(compile(argv[2], "<string>", "exec"), main.__dict__)
    elif argv[0] == sys.executable:  # -m MODULE
        sys.argv = [argv[2], *argv[3:]]
        sys.path[0] = os.getcwd()
        runpy.run_module(argv[2], run_name="__main__", alter_sys=True)
    else:  # a console script of this environment
        sys.argv = list(argv)
        sys.path[0] = os.path.dirname(argv[0])
        runpy.run_path(argv[0], run_name="__main__")


if __name__ == "__main__":
    _request = _serve(sys.argv[1])
    _become(_request)
    _run(_request["argv"])
