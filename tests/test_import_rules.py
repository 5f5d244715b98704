"""The import rules of ../shared/ARCHITECTURE.md and docs/architecture.md, checked by an AST scan.

Every import statement of every module counts, those inside functions too (a lazy
import is still a dependency).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = ("astcom_client", "mount_emulator", "virtualstar", "pointing_model", "catalogs",
        "guide_camera")


def imported(path: Path) -> set[str]:
    """Return the dotted names a module imports (relative imports resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                names.add(".".join([*base, node.module] if node.module else base))
            else:
                names.add(node.module or "")
    return names


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def ours(names: set[str]) -> set[str]:
    return {n for n in names if n.split(".")[0] in OURS}


def offending(paths: list[Path], forbidden: tuple[str, ...]) -> list[str]:
    bad = []
    for path in paths:
        for name in ours(imported(path)):
            if name.split(".")[0] in forbidden or name in forbidden:
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
    return bad


@pytest.mark.parametrize(("package", "forbidden"), [
    ("astcom_client", ("mount_emulator", "virtualstar", "pointing_model", "catalogs",
                       "guide_camera")),
    ("catalogs", ("astcom_client", "mount_emulator", "virtualstar", "pointing_model",
                  "guide_camera")),
    ("mount_emulator", ("virtualstar", "pointing_model", "catalogs", "guide_camera")),
    # the camera simulator: ASTCom and independent truth libraries (skyfield, sgp4, ERFA)
    ("guide_camera", ("mount_emulator", "virtualstar", "pointing_model", "catalogs")),
])
def test_a_package_imports_only_what_the_architecture_allows(package, forbidden):
    assert offending(modules(package), forbidden) == []


def test_the_pointing_model_core_imports_nothing_of_ours_and_its_cli_no_emulator():
    cli = [p for p in modules("pointing_model") if p.name.startswith("cli")]  # cli, cli_sky
    core = [p for p in modules("pointing_model") if p not in cli]
    assert offending(core, ("astcom_client", "mount_emulator", "virtualstar", "catalogs")) == []
    assert offending(cli, ("mount_emulator", "astcom_client")) == []


def test_only_the_launcher_of_virtualstar_imports_the_emulator_and_the_camera_simulator():
    others = [p for p in modules("virtualstar") if p != ROOT / "virtualstar" / "launcher.py"]
    assert offending(others, ("mount_emulator", "guide_camera")) == []


@pytest.mark.parametrize("module", ["frames.py", "boresight.py"])
def test_the_camera_frames_are_pure_functions(module):
    names = imported(ROOT / "guide_camera" / module)
    assert not names & {"time", "datetime", "asyncio", "socket", "astcom_client"}, names


@pytest.mark.parametrize("module", ["protocol.py", "codec.py", "commands.py", "service.py",
                                    "registry.py"])
def test_the_astcom_protocol_core_does_no_io(module):
    names = imported(ROOT / "astcom_client" / module)
    assert not names & {"asyncio", "socket", "websockets", "ssl"}, names


@pytest.mark.parametrize("module", ["physics.py", "model.py"])
def test_the_emulator_physics_reads_no_clock_and_no_socket(module):
    names = imported(ROOT / "mount_emulator" / module)
    assert not names & {"time", "datetime", "asyncio", "socket"}, names


def test_the_vss_reads_no_clock_of_its_own_for_mount_time():
    """The VSS waits on the mount clock (server/clock.py); wall time only for timeouts."""
    allowed = {"clock.py", "timesync.py", "telescope.py", "server.py",  # wall: TimeS, stall, heartbeat
               # a driver without a mount clock: mount time is the host's UTC, each report
               # stamped when it was read (ARCHITECTURE.md, "Time"); its loop paces in wall time
               "rate_mount.py", "indi.py", "rate_loop.py"}
    for path in modules("virtualstar/server"):
        if path.name not in allowed:
            assert not imported(path) & {"time", "datetime"}, path.name


def test_the_vs_root_lists_each_command_with_the_first_paragraph_of_its_own_help():
    """`vs --help` imports no command module, so its summaries are a table: it must not drift."""
    import importlib

    import typer

    from virtualstar.cli.main import COMMANDS

    for name, (module, attribute, summary) in COMMANDS.items():
        target = getattr(importlib.import_module(module), attribute)
        doc = target.info.help if isinstance(target, typer.Typer) else target.__doc__
        assert " ".join(doc.strip().split("\n\n")[0].split()) == summary, name


_EVERY_HELP = r"""
import importlib, json, sys
import typer
HEAVY = {"numpy", "pandas", "pyarrow", "matplotlib", "scipy", "numba", "astropy", "erfa",
         "skyfield", "sgp4", "aiohttp", "websockets"}

def heavy_now():
    return {m.split(".")[0] for m in sys.modules} & HEAVY

def build(module, argv):
    # what --help does up to drawing the text: import the command and build its parameters
    # (the drawing itself, in rich, imports nothing of ours and costs most of the time)
    app = importlib.import_module(module).app
    command = typer.main.get_group(app)
    with command.make_context("prog", ["--help"], resilient_parsing=True) as ctx:
        for name in argv[:-1]:
            command = command.get_command(ctx, name)
            ctx = command.make_context(name, ["--help"], parent=ctx, resilient_parsing=True)
        command.get_params(ctx)

def every_help():
    from virtualstar.cli.main import COMMANDS
    yield "virtualstar.cli.main", ["--help"]
    for name, (module, attribute, _) in COMMANDS.items():
        yield "virtualstar.cli.main", [name, "--help"]
        target = getattr(importlib.import_module(module), attribute)
        if isinstance(target, typer.Typer):
            for sub in typer.main.get_group(target).commands:
                yield "virtualstar.cli.main", [name, sub, "--help"]
    import pointing_model.cli as pm
    yield "pointing_model.cli", ["--help"]
    for sub in typer.main.get_group(pm.app).commands:
        yield "pointing_model.cli", [sub, "--help"]

# One process builds every command in turn. sys.modules only grows, so the heavy libraries
# present after a command are those it or an earlier one imported: a command that imports
# one is the first after which it appears (each name reports what appeared with it), and
# none present after the last means none of them imports any.
results = {}
if heavy_now():
    results["typer"] = sorted(heavy_now())
for module, argv in every_help():
    before = heavy_now()
    try:
        build(module, argv)
    except BaseException as exc:  # noqa: BLE001 - reported to the test
        results[f"{module} {' '.join(argv)}"] = repr(exc)
        continue
    results[f"{module} {' '.join(argv)}"] = sorted(heavy_now() - before)
print(json.dumps(results))
"""


def test_every_help_imports_none_of_the_heavy_libraries():
    """Every `vs ... --help` and `pointing-model ... --help` stays under 0.3 s: none imports
    numpy, pyarrow, scipy, the astronomy, aiohttp or websockets (benchmarks/bench_cli_startup.py
    times them). Each command is built as its --help builds it, one after another in one
    process that imported only typer (_EVERY_HELP says why that is proof enough)."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _EVERY_HELP], capture_output=True, text=True,
                         cwd=ROOT, timeout=300)
    results = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(results) > 30, results  # every command and subcommand was reached
    heavy = {argv: mods for argv, mods in results.items() if mods}
    assert heavy == {}, heavy


@pytest.mark.parametrize("argv", [["--help"], ["status", "--server", "ws://127.0.0.1:9"],
                                  ["slew", "--help"]])
def test_vs_help_and_status_import_none_of_the_heavy_libraries(argv):
    """The CLI starts in a fraction of a second: numpy, pandas, pyarrow, matplotlib, scipy
    and numba stay unimported for help and for the client commands."""
    import subprocess
    import sys

    code = ("import sys\nfrom virtualstar.cli.main import app\n"
            f"sys.argv = ['vs', *{argv!r}]\n"
            "try:\n    app()\nexcept SystemExit:\n    pass\n"
            "heavy = ('numpy', 'pandas', 'pyarrow', 'matplotlib', 'scipy', 'numba', 'astropy')\n"
            "print(sorted({m.split('.')[0] for m in sys.modules if m.split('.')[0] in heavy}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr


@pytest.mark.parametrize("package", ["virtualstar/alpaca", "virtualstar/indi"])
def test_the_facades_reach_the_mount_only_through_a_vss_client(package):
    """Alpaca and INDI translate to VSS commands: no emulator, no ASTCom client, no server
    internals (the in-process client is handed to them by the launcher or the CLI)."""
    forbidden = ("mount_emulator", "virtualstar.server", "virtualstar.launcher",
                 "astcom_client.client", "astcom_client.endpoint")
    for path in modules(package):
        for name in ours(imported(path)):
            assert not any(name == f or name.startswith(f + ".") for f in forbidden), \
                f"{path.relative_to(ROOT)} imports {name}"


@pytest.mark.parametrize("module", ["virtualstar.alpaca", "virtualstar.indi.driver"])
def test_the_facades_start_without_scipy_or_numba(module):
    """The façades convert coordinates with ERFA alone: importing one (as `vs alpaca` and
    `vs-indi` do at start) loads the astronomy package's names lazily, so neither scipy's
    splines nor numba's kernels are imported (~0.8 s of CPU at each start)."""
    import subprocess
    import sys

    code = (f"import sys\nimport {module}\n"
            "print(sorted({m for m in ('scipy', 'numba', 'skyfield') if m in sys.modules}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr


def test_the_astronomy_package_names_every_public_name_and_loads_it_when_used():
    """`virtualstar.astro` imports its modules when a name is first used (PEP 562): every
    name in __all__ resolves to the object its module defines, and an unknown name raises
    AttributeError as a plain module would."""
    import importlib

    import virtualstar.astro as astro

    for name in astro.__all__:
        value = getattr(astro, name)
        assert getattr(importlib.import_module(f"virtualstar.astro.{astro._MODULE_OF[name]}"),
                       name) is value, name
    assert set(astro.__all__) <= set(dir(astro))
    assert set(astro._MODULE_OF) == set(astro.__all__)  # the two lists of names kept alike
    with pytest.raises(AttributeError, match="no_such_name"):
        astro.no_such_name  # noqa: B018


@pytest.mark.parametrize("module", ["virtualstar/alpaca/protocol.py", "virtualstar/indi/protocol.py"])
def test_the_facade_protocols_do_no_io(module):
    names = imported(ROOT / module)
    assert not names & {"asyncio", "socket", "aiohttp", "websockets", "sys"}, names


@pytest.mark.parametrize("module", ["procedures.py", "programs.py"])
def test_the_procedures_see_the_server_only_through_the_station_view(module):
    """Issue 26's import circle: procedures and programs take a `Station` (station.py), a
    narrow view of the server, and never import the telescope, even for typing."""
    names = imported(ROOT / "virtualstar" / "server" / module)
    assert "virtualstar.server.telescope" not in names, names


def test_mount_backends_import_no_supervisor_internals():
    """A backend implements the mount-link interface and nothing more: it may import the
    interface, the mapping, the exceptions, astronomy and its protocol's client library."""
    allowed = {"virtualstar.server.link_interface", "virtualstar.server.mapping",
               "virtualstar.server.exceptions", "virtualstar.server.operations"}
    for path in modules("virtualstar/server/backends"):
        for name in ours(imported(path)):
            if name.startswith("virtualstar.server.") and not name.startswith(
                    "virtualstar.server.backends"):
                assert name in allowed, f"{path.relative_to(ROOT)} imports {name}"
            assert not name.startswith(("mount_emulator", "virtualstar.launcher")), name
