"""The command line's start-up: what a run imports, and the shortcuts that keep it quick give Typer's own results.

No timing is asserted (``benchmarks/bench_startup.py`` measures it): these tests check *which* modules a run
loads, and that the shortcuts of :mod:`delaykit.cli.common` (option values converted without pydantic, the group
built with the one command being run, the consoles made on first use) change nothing a user sees.
"""

from __future__ import annotations

import io
import json
import math
import os
import random
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PAPER = ["simulate", "--kp", "1.31", "--delay", "0.368", "--json"]
GENERAL = ["simulate", "--plant", "1/(s*(0.05*s+1))", "--delay", "0.3", "--controller", "pd", "--kp", "2", "--kd",
           "0.1", "--derivative-filter", "0.02", "--umin", "-1", "--umax", "3", "--step", "-1", "--json"]
# what a short simulation does not need: the compiled kernels, SciPy, plotting, and what only Typer's slow paths
# (pydantic's conversion), tables and the other commands load
NOT_FOR_SIMULATE = ("scipy", "scipy.optimize", "matplotlib", "pydantic", "rich.console", "rich.table",
                    "delaykit.cli.cmd_design", "delaykit.cli.cmd_hardware", "delaykit.cli.cmd_identify",
                    "delaykit.cli.cmd_paper", "delaykit.cli.cmd_spectrum")


def _run_main(args: list[str]) -> tuple[dict, str]:
    """Run ``delaykit ARGS`` as the console script does (``delaykit.cli.main``) in a fresh interpreter; return
    the heavy modules it loaded and what it printed before that."""
    code = textwrap.dedent(f"""
        import json, sys
        from delaykit.cli import main
        sys.argv = ["delaykit", *{args!r}]
        try:
            main()
        except SystemExit as exc:
            assert not exc.code, exc.code
        mods = {NOT_FOR_SIMULATE + ("numba", "numpy", "delaykit.paper.data")!r}
        print("@@" + json.dumps({{m: m in sys.modules for m in mods}}))
    """)
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    printed, _, loaded = run.stdout.rpartition("@@")
    return json.loads(loaded), printed


def test_simulate_of_the_paper_loop_loads_neither_numba_nor_scipy_nor_matplotlib():
    from delaykit import AltitudeLoop
    from delaykit.simulate.simulation import simulate

    loaded, printed = _run_main(PAPER)
    assert loaded["numpy"]  # the guard: the run did simulate
    heavy = [m for m in ("numba", *NOT_FOR_SIMULATE) if loaded[m]]
    assert not heavy, f"`delaykit {' '.join(PAPER)}` imported {heavy}"
    # and it printed the library's result (computed here, in this process, compiled)
    got = json.loads(printed)
    ref = simulate(AltitudeLoop(kp=1.31, delay=0.368)).metrics
    assert got["overshoot"] == pytest.approx(ref.overshoot, rel=1e-12, abs=1e-12)
    assert got["settling_time"] == pytest.approx(ref.settling_time, rel=1e-12, abs=1e-12)


def test_simulate_of_a_general_loop_loads_no_scipy_matplotlib_or_pydantic():
    # numba is not checked here: whether this loop fits the interpreter's budget of pieces is the kernel's
    # business (tests/test_kernel_modes.py); what the command line itself loads is not
    loaded, printed = _run_main(GENERAL)
    assert loaded["numpy"]
    heavy = [m for m in (*NOT_FOR_SIMULATE, "delaykit.paper.data") if loaded[m]]  # not the paper's loop
    assert not heavy, f"`delaykit {' '.join(GENERAL)}` imported {heavy}"
    got = json.loads(printed)
    assert got["loop"]["controller"]["kind"] == "pd" and got["step"] == -1.0


def test_help_loads_no_numpy():
    code = ("import sys\nfrom delaykit.cli import main\nsys.argv = ['delaykit', '--help']\ntry:\n    main()\n"
            "except SystemExit as exc:\n    assert not exc.code\n"
            "print('@@' + ','.join(m for m in ('numpy', 'numba', 'scipy', 'matplotlib', 'pydantic') "
            "if m in sys.modules))\n")
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    help_text, _, loaded = run.stdout.rpartition("@@")
    assert loaded.strip() == ""
    for name in ("simulate", "margins", "estimate", "design", "fly", "demo"):  # every panel's commands listed
        assert name in help_text


# ---- the shortcuts give Typer's own results ----

def _typer_and_quick(command_name: str):
    """Each option of a command: Typer's own conversion (pydantic's) and the quick one, side by side."""
    import typer.main
    from typer._coercion import build_runtime_param

    from delaykit.cli import app
    from delaykit.cli.common import _QuickCoercion

    command = typer.main.get_command(app).commands[command_name]
    ctx = command.make_context(command_name, [], resilient_parsing=True)
    return [(p, build_runtime_param(p.type_descriptor), _QuickCoercion(p, build_runtime_param), ctx)
            for p in command.params]


def _typer_value(real, param, ctx, text):
    try:
        return ("ok", real.coerce(text, param=param, ctx=ctx))
    except Exception as exc:  # typer's message, whatever its class
        return ("error", type(exc).__name__, str(exc))


def test_quick_conversion_of_numbers_equals_pydantics():
    # the reference is Typer's own conversion (a pydantic TypeAdapter); the texts are the plain numbers the quick
    # path takes, random ones at full precision among them, and forms it must leave to Typer
    rng = random.Random(2026)
    floats = ["0", "-0", "1", "-1", "2", "0.368", "1.31", "-1.5", "1e-3", "2E+5", "3e0", "12345678901234567890",
              "0.1000000000000000055511151231257827", "1e99", "-9.99e-99"]
    floats += [repr(rng.uniform(-1e3, 1e3)) for _ in range(200)] + [f"{rng.lognormvariate(0, 8):.17g}"
                                                                     for _ in range(200)]
    leave = ["1_000", "inf", "-inf", "nan", " 5", "5 ", "+1", ".5", "5.", "007", "1e999", "0x10", "1e", "", "abc",
             "1,5", "١٢"]
    ints = ["0", "-0", "7", "-12", "2026", "123456789012345678"]
    checked = {float: 0, int: 0, str: 0}
    for command in ("simulate", "margins"):
        for param, real, quick, ctx in _typer_and_quick(command):
            kind = quick.kind
            if kind is None:
                continue
            texts = floats + leave if kind is float else ints + leave + floats[:5] if kind is int else \
                floats[:5] + leave
            for text in texts:
                got = quick.quick(text)
                want = _typer_value(real, param, ctx, text)
                if got is _missing():
                    continue  # left to Typer: nothing to compare
                assert want[0] == "ok", f"{param.name} {text!r}: quick gave {got!r}, Typer refuses it: {want}"
                assert type(got) is type(want[1]) and (got == want[1] or (got != got and want[1] != want[1])), \
                    f"{param.name} {text!r}: quick {got!r}, Typer {want[1]!r}"
                if kind is float:
                    assert math.copysign(1.0, got) == math.copysign(1.0, want[1])  # -0.0 stays -0.0
                checked[kind] += 1
            for text in leave:  # the forms Typer reads its own way, or refuses with its own message
                if kind is not str:
                    assert quick.quick(text) is _missing(), f"{param.name} {text!r} should be left to Typer"
    assert checked[float] > 400 and checked[int] > 0 and checked[str] > 0


def _missing():
    from delaykit.cli.common import _MISSING

    return _MISSING


def test_quick_conversion_leaves_absent_and_default_values_as_typer_does():
    for param, real, quick, ctx in _typer_and_quick("simulate"):
        assert quick.quick(None) is None and real.coerce(None, param=param, ctx=ctx) is None
        default = param.default
        if default is not None and not callable(default):
            got = quick.quick(default)
            if got is not _missing():
                assert got == real.coerce(default, param=param, ctx=ctx) and type(got) is type(default)


_COMPARE = textwrap.dedent("""
    import contextlib, io, json, sys
    import typer.main
    from delaykit.cli import app

    def run(command, args):
        out, err = io.StringIO(), io.StringIO()
        code = 0
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                command(args, prog_name="delaykit", standalone_mode=True)
            except SystemExit as exc:
                code = exc.code
        return [code, out.getvalue(), err.getvalue()]

    cases = json.loads(sys.argv[1])
    result = []
    for args in cases:
        fast = run(lambda a, **k: app(a, **k), args)  # the script's way: one command's group, quick conversion
        full = run(typer.main.get_command(app), args)  # Typer's way: every command, pydantic's conversion
        result.append([args, fast, full])
    print(json.dumps(result))
""")


def test_running_one_command_gives_the_whole_groups_help_errors_and_output():
    cases = [[name, "--help"] for name in ("simulate", "roots", "margins", "lambert", "estimate", "identify",
                                           "predict", "design", "emulate", "fly", "reproduce", "report", "demo")]
    cases += [["--help"], ["simulat", "--kp", "1"], ["simulate", "--kp", "abc", "--delay", "0.3"],
              ["simulate", "--kp", "1.31", "--delay", "0.368", "--bogus"], ["simulate", "--kp"],
              ["simulate", "--kp", "1.31", "--delay", "0.368", "--seed", "x"],
              ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "inf", "--json"],
              ["simulate", "--kp", "1.31", "--delay", "-1", "--json"],
              ["roots", "--kp", "1.31", "--delay", "0.368", "--region", "-5", "1", "0", "x", "--json"],
              ["lambert", "--a0", "0", "--a1", "-1", "--delay", "1", "--json"],
              ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "1_0", "--json"]]
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""), "COLUMNS": "100"}
    run = subprocess.run([sys.executable, "-c", _COMPARE, json.dumps(cases)], capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    results = json.loads(run.stdout)
    assert len(results) == len(cases)
    codes = set()
    for args, fast, full in results:
        assert fast == full, f"delaykit {' '.join(args)}: the script's run differs from Typer's"
        codes.add(fast[0])
        if args[-1] == "--help":
            assert "Usage: delaykit" in fast[1]
    assert codes == {0, 2}  # the cases include successes and usage errors


def test_single_command_group_imports_only_its_module():
    code = textwrap.dedent("""
        import sys
        from delaykit.cli import app
        group = app.click_command("lambert")
        print(sorted(group.commands), sorted(m for m in sys.modules if m.startswith("delaykit.cli.cmd_")))
    """)
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "['lambert'] ['delaykit.cli.cmd_spectrum']"


def test_every_command_is_registered_in_order_when_the_list_is_read():
    from delaykit.cli import app
    from delaykit.cli.app import COMMANDS

    names = [c.callback.__name__ for c in app.registered_commands]
    assert names == [function for _, commands in COMMANDS for _, function in commands]
    panels = [c.rich_help_panel for c in app.registered_commands]
    assert panels == [panel for panel, commands in COMMANDS for _ in commands]


def test_the_status_spinner_is_skipped_only_where_rich_would_draw_nothing(monkeypatch):
    from delaykit.cli.common import _LazyConsole, _NoStatus

    for var in ("TTY_COMPATIBLE", "FORCE_COLOR"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal
    lazy = _LazyConsole(stderr=True)
    with lazy.status("working") as st:
        st.update("still working")
    assert isinstance(lazy.status("x"), _NoStatus) and lazy._console is None
    # where rich would draw (told so by FORCE_COLOR), the real spinner, on the real console
    monkeypatch.setenv("FORCE_COLOR", "1")
    from rich.status import Status

    assert isinstance(lazy.status("x"), Status)
    # and a console, once made, is rich's own, printing where it is told
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    monkeypatch.delenv("FORCE_COLOR")
    fresh = _LazyConsole(stderr=True)
    fresh.print("hello", highlight=False)
    assert buf.getvalue() == "hello\n"


@pytest.mark.parametrize("preset", [None, "2"])
def test_the_command_asks_blas_for_one_thread_unless_the_user_said(preset):
    # measured by threadpoolctl in the command's own process, after it has run (numpy loaded by then): one
    # OpenBLAS thread by default, the user's number where OPENBLAS_NUM_THREADS was set
    pytest.importorskip("threadpoolctl")
    code = textwrap.dedent(f"""
        import json, sys
        sys.argv = ["delaykit", *{PAPER!r}]
        from delaykit.cli import main
        try:
            main()
        except SystemExit:
            pass
        from threadpoolctl import threadpool_info
        print("@@" + json.dumps([p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]))
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                                            "OMP_NUM_THREADS")}
    env["PYTHONPATH"] = str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")
    if preset:
        env["OPENBLAS_NUM_THREADS"] = preset
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    threads = json.loads(run.stdout.rpartition("@@")[2])
    if not threads:
        pytest.skip("numpy's BLAS is not one threadpoolctl sees")
    want = int(preset) if preset else 1
    assert all(n == min(want, os.cpu_count() or want) for n in threads), threads
