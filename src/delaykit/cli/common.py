"""The command line's shared pieces: the Typer application, the consoles, the error wrapper, parsers and formatters."""

from __future__ import annotations

import contextlib
import csv
import functools
import math
import re
from pathlib import Path
from typing import Any, Callable, Iterator, Optional

import typer
from typer.core import TyperGroup

from ..errors import DelaykitError, InvalidValueError, RangeSpecError

__all__ = [
    "app", "check_output", "ci_list", "confirm_real", "err", "fmt", "fmt_ci", "friendly", "one_line", "out",
    "help_text", "parse_delays", "parse_schedule", "print_error", "print_json", "print_rms", "progress_bar",
    "quick_coercion", "read_delay_trace", "run_until_stopped", "strict_json", "warn",
]

_MISSING = object()
_FLOAT_TEXT = re.compile(r"-?(?:0|[1-9][0-9]{0,19})(?:\.[0-9]{1,20})?(?:[eE][-+]?[0-9]{1,2})?")
_INT_TEXT = re.compile(r"-?(?:0|[1-9][0-9]{0,17})")


class _QuickCoercion:
    """Typer's conversion of one option's value, without pydantic where the value is plain.

    Recent Typer (0.29 here) converts every option's value, given or not, through a pydantic ``TypeAdapter``
    built for it, and importing pydantic and building the adapters of a command's 45 options takes a sixth of a
    second.
    For an option that is absent (``None``), a value of the option's own type (its default), or a number written
    plainly (``-1``, ``0.368``, ``2e-3``: text that pydantic and Python's ``float``/``int`` read alike) the
    result is the same computed here; any other value (a path, ``1_000``, ``inf``, a bad number) goes to
    typer's own conversion, built the first time it is needed, which gives typer's result and its error message.
    """

    def __init__(self, param: Any, build: Callable[[Any], Any]) -> None:
        self.param, self.build, self.real = param, build, None
        desc = param.type_descriptor
        info = desc.parameter_info
        plain = (desc.file_annotation is None and getattr(info, "parser", None) is None
                 and getattr(info, "min", None) is None and getattr(info, "max", None) is None
                 and not getattr(info, "clamp", False) and not param.multiple and param.nargs == 1)
        self.kind = desc.annotation if plain and desc.annotation in (float, int, str) else None
        self.single = not param.multiple and param.nargs == 1
        self.number = _number_kind(desc.annotation)

    def quick(self, value: Any) -> Any:
        """The converted value, or ``_MISSING`` where typer's own conversion must decide."""
        if value is None and self.single:
            return None
        kind = self.kind
        if kind is None and type(value) is bool and self.param.type_descriptor.annotation is bool:
            return value  # a flag: what typer does too
        if kind is None:
            return _MISSING
        if type(value) is kind:
            return value
        if type(value) is str:
            if kind is float and _FLOAT_TEXT.fullmatch(value):
                return float(value)
            if kind is int and _INT_TEXT.fullmatch(value):
                return int(value)
        return _MISSING

    def coerce(self, value: Any, param: Any, ctx: Any) -> Any:
        got = self.quick(value)
        if got is not _MISSING:
            return got
        if self.number is not None:  # the ASCII-decimal rule first: pydantic and float() read 1_0 as ten
            _check_number_text(value, self.number, param, ctx)
        if self.real is None:
            self.real = self.build(self.param.type_descriptor)
        return self.real.coerce(value, param=param, ctx=ctx)


def _number_kind(annotation: Any) -> Any:
    """``float`` or ``int`` for an option of numbers (``float``, ``Optional[int]``, ``tuple[float, ...]``,
    ``list[int]``), else None."""
    import typing

    if annotation in (float, int):
        return annotation
    kinds = {_number_kind(a) for a in typing.get_args(annotation) if a is not type(None) and a is not Ellipsis}
    return kinds.pop() if len(kinds) == 1 and None not in kinds else None


def _check_number_text(value: Any, kind: Any, param: Any, ctx: Any) -> None:
    """Raise click's BadParameter for text in ``value`` (one text, or a tuple or list of them) that is not a
    number in ASCII decimal (:func:`~delaykit.models.ranges.parse_number`; an integer for ``int``)."""
    from ..models.ranges import parse_integer, parse_number

    for text in value if isinstance(value, (tuple, list)) else (value,):
        if isinstance(text, str):
            try:
                (parse_integer if kind is int else parse_number)(text)
            except InvalidValueError:
                what = "an integer (ASCII decimal, e.g. 12)" if kind is int else \
                    "a number (ASCII decimal, e.g. -1.5 or 2e-3)"
                raise typer.BadParameter(f"{text[:40]!r} is not {what}", ctx=ctx, param=param) from None


def quick_coercion(command: Any) -> int:
    """Give every option of a Typer-built click command (and its subcommands) a :class:`_QuickCoercion`.

    Returns how many options got one (0 with a Typer that converts values without pydantic, where there is
    nothing to gain: the command is then left as it is; 0 again for options that have one already).  The
    application's group calls it when it is built, so that every way of running a command (the ``delaykit``
    script, ``typer.main.get_command``, Typer's test runner) reads numbers by the same rule.

    Examples
    --------
    >>> import typer.main
    >>> from delaykit.cli import app
    >>> group = typer.main.get_command(app)
    >>> type(group.commands["simulate"].params[0]._runtime_param).__name__, quick_coercion(group)
    ('_QuickCoercion', 0)
    """
    try:
        from typer._coercion import build_runtime_param
    except ImportError:  # a Typer without pydantic coercion
        return 0

    def install(param: Any) -> int:
        if getattr(param, "_runtime_param", _MISSING) is None and hasattr(param, "type_descriptor"):
            param._runtime_param = _QuickCoercion(param, build_runtime_param)
            return 1
        return 0

    def with_help(get_help_option: Callable[[Any], Any]) -> Callable[[Any], Any]:
        def get(ctx: Any) -> Any:  # the --help option, made when the command first parses
            option = get_help_option(ctx)
            if option is not None:
                install(option)
            return option

        return get

    count = 0
    stack = [command]
    while stack:
        cmd = stack.pop()
        stack.extend(getattr(cmd, "commands", {}).values())
        count += sum(install(param) for param in getattr(cmd, "params", ()))
        if callable(getattr(cmd, "get_help_option", None)):
            cmd.get_help_option = with_help(cmd.get_help_option)
    return count


class _App(typer.Typer):
    """The Typer application: its commands imported when needed, and built for the command being run only.

    * :meth:`add_lazy_command` registers a command by the module and name of its function; the module is
      imported the first time the commands are read (``registered_commands``: Typer's help, its test runner),
      so that ``import delaykit.cli`` does not load every command's module.
    * Run (``app()``, the ``delaykit`` script) with a first argument that names a lazily registered command
      (``delaykit simulate ...``), the click group is built with that command alone, from its module alone:
      Typer would otherwise import all six command modules and read the signatures and build the options of
      all thirteen commands (some 25 ms, and more where Python compiles the modules afresh) to run one.  The
      command's parsing, help and errors are the same either way (the tests compare them); anything else
      (``--help``, no command, a misspelt one) gets the whole group.
    * Every option's value is converted by :func:`quick_coercion`.

    The click command is built at each call, as Typer's own ``__call__`` does (with
    ``pretty_exceptions_enable=False`` Typer's exception hook only passes an exception on, so it is not
    installed here).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._lazy: list[tuple[str, str, str]] = []  # (module, function, help panel), in the order registered
        self._loaded = True
        self._commands: list[Any] = []
        super().__init__(*args, **kwargs)

    @property  # type: ignore[override]
    def registered_commands(self) -> list[Any]:
        """Typer's list of commands: importing the lazily registered ones' modules the first time it is read."""
        if not self._loaded:
            self._loaded = True
            for module, function, panel in self._lazy:
                fn = _function(module, function)
                self.command(help=help_text(fn), rich_help_panel=panel)(fn)
        return self._commands

    @registered_commands.setter
    def registered_commands(self, value: list[Any]) -> None:
        self._commands = value

    def add_lazy_command(self, module: str, function: str, panel: str) -> None:
        """Register the command ``function`` of ``module`` (a full module name) under the help panel ``panel``;
        the module is imported when the command is needed.

        Examples
        --------
        >>> from delaykit.cli.app import COMMANDS, app
        >>> len(app._lazy) == sum(len(commands) for _, commands in COMMANDS)  # what delaykit.cli.app registers
        True
        """
        self._lazy.append((module, function, panel))
        self._loaded = False

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        argv = kwargs["args"] if "args" in kwargs else args[0] if args else None
        if argv is None:
            import sys

            argv = sys.argv[1:]
        first = next(iter(argv), None) if not isinstance(argv, str) else None
        command = self.click_command(first if isinstance(first, str) else None)
        quick_coercion(command)
        return command(*args, **kwargs)

    def click_command(self, name: Optional[str] = None) -> Any:
        """The click group: with the lazily registered command ``name`` alone where there is one, else with every
        command.

        Examples
        --------
        >>> from delaykit.cli import app
        >>> from delaykit.cli.app import COMMANDS
        >>> sorted(app.click_command("lambert").commands)
        ['lambert']
        >>> len(app.click_command().commands) == sum(len(commands) for _, commands in COMMANDS)
        True
        """
        import copy

        import typer.main

        if name is not None and self.registered_callback is None and not self.registered_groups \
                and not getattr(self, "_add_completion", True):
            named = getattr(typer.main, "get_command_name", lambda n: n.lower().replace("_", "-"))
            chosen = [(module, function, panel) for module, function, panel in self._lazy if named(function) == name]
            if len(chosen) == 1:
                module, function, panel = chosen[0]
                scratch = typer.Typer()
                fn = _function(module, function)
                scratch.command(help=help_text(fn), rich_help_panel=panel)(fn)
                one = copy.copy(self)
                one._loaded, one._commands = True, list(scratch.registered_commands)
                return typer.main.get_group(one)
        return typer.main.get_command(self)


def help_text(fn: Any) -> Optional[str]:
    """A command's help: its docstring with each paragraph's lines joined, for the terminal to wrap.

    The docstrings are wrapped at 120 columns in the source; printed as they are, a terminal of 80 columns
    breaks every line again, mid-sentence.  Lines of a list (``-``, ``*``, ``1.``) or indented ones keep their
    breaks.

    Examples
    --------
    >>> def f():
    ...     \"\"\"First line.
    ...
    ...     A paragraph written
    ...     on two lines.
    ...
    ...     - an item
    ...     - another\"\"\"
    >>> help_text(f)
    'First line.\\n\\nA paragraph written on two lines.\\n\\n- an item\\n- another'
    """
    import inspect

    doc = inspect.getdoc(fn)
    if not doc:
        return None
    out = []
    for para in doc.split("\n\n"):
        lines = para.split("\n")
        listed = any(ln.startswith((" ", "- ", "* ", "\u2022 ")) or ln.split(" ", 1)[0].rstrip(".").isdigit()
                     for ln in lines)
        out.append(para if listed else " ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


def _function(module: str, name: str) -> Any:
    from importlib import import_module

    return getattr(import_module(module), name)


class _Group(TyperGroup):
    """Typer's command group, with its usage errors (a bad option value, an unknown option, a missing one) on one
    line, ``error: ... (see 'delaykit CMD --help')``, exit status 2, as delaykit's own errors (Typer would draw a
    box around the message, wrapped to the terminal's width, after two lines of usage)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        quick_coercion(self)  # however the group is built (the script, typer.main.get_command, the test runner)

    def main(self, args: Any = None, prog_name: Optional[str] = None, complete_var: Optional[str] = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        import sys

        # click's ClickException (Typer's own copy of click, or click itself in older Typer): the base of its errors
        usage = next(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException")
        try:
            code = super().main(args, prog_name, complete_var, False, **extra)
        except usage as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # no command: the help, as Typer shows it
                return super().main(args, prog_name, complete_var, True, **extra)
            ctx = getattr(exc, "ctx", None)
            where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
            print_error(exc.format_message().rstrip(".") + where)
            sys.exit(exc.exit_code)
        except typer.Abort:
            print_error("aborted")
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = _App(
    help="delaykit: feedback loops with a time delay (the quadrotor altitude loop of Armah & Yi).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=_Group,
)


class _NoStatus:
    """What :meth:`_LazyConsole.status` and :func:`progress_bar` give where rich would draw nothing: a context that
    does nothing."""

    def __enter__(self) -> "_NoStatus":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    def update(self, *args: Any, **kwargs: Any) -> None:
        """Ignore a new status message (or a task's progress)."""

    def add_task(self, *args: Any, **kwargs: Any) -> int:
        """A task of a progress bar that is not drawn."""
        return 0

    def advance(self, *args: Any, **kwargs: Any) -> None:
        """Ignore a task's progress."""

    def start(self) -> None:
        """Nothing to start."""

    def stop(self) -> None:
        """Nothing to stop."""


class _LazyConsole:
    """A rich ``Console`` made on first use (importing rich's console costs some 40 ms, which a ``--json`` run
    that prints with ``print`` need not pay); every attribute is the console's.

    :meth:`status` draws a spinner only where rich would: on a terminal (or where ``TTY_COMPATIBLE`` or
    ``FORCE_COLOR`` says there is one), or in Jupyter; elsewhere rich's spinner prints nothing, and this one does
    not make the console to print it.
    """

    def __init__(self, **kwargs: Any) -> None:
        self._kwargs = kwargs
        self._console: Any = None

    @property
    def console(self) -> Any:
        """The rich ``Console`` itself (made now if it was not), for code that takes a console."""
        if self._console is None:
            from rich.console import Console

            self._console = Console(**self._kwargs)
        return self._console

    def __getattr__(self, name: str) -> Any:
        return getattr(self.console, name)

    def status(self, *args: Any, **kwargs: Any) -> Any:
        """``Console.status``, or a context that does nothing where rich's spinner would print nothing."""
        if self._console is None and not self._may_draw():
            return _NoStatus()
        from rich.status import Status
        from rich.text import Text

        class PlainStatus(Status):  # its messages plain text, never markup
            def update(self, status: Any = None, **kw: Any) -> None:
                super().update(Text(one_line(status)) if isinstance(status, str) else status, **kw)

        if args and isinstance(args[0], str):
            args = (Text(one_line(args[0])), *args[1:])
        return PlainStatus(*args, console=self.console, **kwargs)

    def _may_draw(self) -> bool:
        import os
        import sys

        if os.environ.get("TTY_COMPATIBLE") is not None or os.environ.get("FORCE_COLOR") is not None:
            return True
        if "IPython" in sys.modules:  # a notebook: rich draws in the cell
            return True
        stream = sys.stderr if self._kwargs.get("stderr") else sys.stdout
        try:
            return bool(stream.isatty())
        except (AttributeError, ValueError):
            return False


# Neither console reads markup (``[b]``, ``[/]``) or emoji codes (``:b:``) in the text it prints, titles and table
# cells included: that text holds the user's values (a file name, a plant, a range), printed as written; styles come
# as rich ``Text`` (see print_error and warn).  Neither wraps what it prints: an error stays one line however
# narrow the terminal, and a message that is not on a terminal is not cut at 80 columns.
out: Any = _LazyConsole(soft_wrap=True, markup=False, emoji=False, highlight=False)
err: Any = _LazyConsole(stderr=True, soft_wrap=True, markup=False, emoji=False, highlight=False)


def one_line(text: str) -> str:
    """``text`` as one printable line: control characters (a newline, a tab, a terminal escape) written as Python
    escapes, every other character as it is.

    Examples
    --------
    >>> one_line("a[/]b\\tc\\nd:b:")
    'a[/]b\\\\tc\\\\nd:b:'
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def print_error(message: str) -> None:
    """Print ``error: MESSAGE`` on stderr: one line, the message as it is (no markup, no emoji, no wrapping)."""
    from rich.text import Text

    err.print(Text.assemble(("error:", "bold red"), " ", one_line(str(message))))


def warn(message: str, label: str = "warning") -> None:
    """Print ``LABEL: MESSAGE`` (``warning: ...`` by default) on stdout, among the results: one line, the message
    as it is."""
    from rich.text import Text

    out.print(Text.assemble((f"{label}:", "yellow"), " ", one_line(str(message))))


def friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn delaykit's errors into one line on stderr and exit status 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DelaykitError as exc:
            print_error(str(exc))
            raise typer.Exit(2) from None

    return wrapper


def parse_delays(spec: str) -> list[float]:
    """Delays from ``0.368``, ``START:STOP:N``, ``a,b,c`` or ``table1`` (the K·Ts of the paper's Table 1).

    Examples
    --------
    >>> parse_delays("0.2:0.5:4")
    [0.2, 0.3, 0.4, 0.5]
    >>> len(parse_delays("table1"))
    7
    """
    from ..models.ranges import parse_range

    spec = spec.strip()
    if spec.lower() == "table1":
        from ..models.altitude import PAPER_PERIOD
        from ..paper.data import TABLE1

        return [k * PAPER_PERIOD for k, _, _ in TABLE1]
    try:
        return parse_range(spec, "--delay")
    except RangeSpecError:
        raise RangeSpecError(f"--delay {spec!r} is not a delay: give seconds (0.368), START:STOP:N, a comma "
                             "list, or 'table1'") from None


def parse_schedule(spec: str) -> list[tuple[float, float]]:
    """A delay schedule from ``T:DELAY`` pairs separated by commas (times and delays in seconds): finite, the
    delays at least 0, the times increasing; an error names the bad item as the user wrote it.

    Examples
    --------
    >>> parse_schedule("20:0.40, 40:0.25")
    [(20.0, 0.4), (40.0, 0.25)]
    """
    from ..models.budget import MAX_RANGE_POINTS, check_count, shorten

    pairs: list[tuple[float, float]] = []
    items = [x.strip() for x in spec.split(",")]
    check_count("--delay-schedule", len(items), MAX_RANGE_POINTS, "items")
    q = lambda x: repr(shorten(x, 40))  # noqa: E731  (an item quoted in a refusal stays short)
    for k, item in enumerate(items):
        parts = item.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            from ..models.ranges import parse_number  # (ASCII decimal: float() also reads 1_0 and '１２')

            t, d = parse_number(parts[0]), parse_number(parts[1])
        except ValueError:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {q(item)} is not T:DELAY (seconds since "
                                    "start, delay in seconds), e.g. 20:0.40") from None
        if not (math.isfinite(t) and math.isfinite(d)):
            raise InvalidValueError(f"--delay-schedule item {k + 1} {q(item)}: the time and the delay must be "
                                    "finite numbers")
        if d < 0:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {q(item)}: the delay {d:g} s is negative "
                                    "(a delay is at least 0 s)")
        if pairs and not t > pairs[-1][0]:
            raise InvalidValueError(f"--delay-schedule times must increase: item {k + 1} {q(item)} (t = {t:g} s) "
                                    f"is not after item {k} {q(items[k - 1])} (t = {pairs[-1][0]:g} s)")
        pairs.append((t, d))
    return pairs


def strict_json(data: Any) -> Any:
    """``data`` made fit for strict JSON: every number that is not finite (inf, -inf, nan) becomes ``None``
    (null), and each dict that held one, directly or in a list, gets a ``status`` (``null_status`` where it has a
    status of its own) that names the values and what they were.

    Examples
    --------
    >>> strict_json({"overshoot": float("inf"), "peak_time": 4.0, "rightmost": [float("-inf"), float("nan")]})
    {'overshoot': None, 'peak_time': 4.0, 'rightmost': [None, None], 'status': 'not finite, written as null: \
overshoot = inf, rightmost[0] = -inf, rightmost[1] = nan'}
    """
    import numbers

    def walk(v: Any) -> tuple[Any, list[tuple[str, str]]]:
        if isinstance(v, float) or isinstance(v, numbers.Real) and not isinstance(v, numbers.Integral):
            x = float(v)
            return (x, []) if math.isfinite(x) else (None, [("", str(x))])
        if isinstance(v, dict):
            clean, said = {}, []
            for k, x in v.items():
                clean[k], bad = walk(x)
                said += [(f"{k}{path}", what) for path, what in bad]
            if said:
                key = "null_status" if "status" in clean else "status"
                clean[key] = "not finite, written as null: " + ", ".join(f"{p} = {w}" for p, w in said)
            return clean, []
        if isinstance(v, (list, tuple)):
            items, said = [], []
            for i, x in enumerate(v):
                c, bad = walk(x)
                items.append(c)
                said += [(f"[{i}]{path}", what) for path, what in bad]
            return items, said
        return v, []

    return walk(data)[0]


def print_json(data: Any, indent: Optional[int] = 2, default: Optional[Callable[[Any], Any]] = None) -> None:
    """Print ``data`` as strict JSON on stdout (see :func:`strict_json`: never NaN or Infinity)."""
    import json

    print(json.dumps(strict_json(data), indent=indent, allow_nan=False, default=default))


def progress_bar(*, spinner: bool = False) -> Any:
    """A transient rich progress bar on stderr whose task descriptions print as written (never as markup): a bar
    with the share done and the time left, or with ``spinner`` a spinner and the time elapsed.  Where rich would
    draw nothing (stderr not a terminal), one that does nothing: rich's would still leave an empty line behind."""
    if not err._may_draw():
        return _NoStatus()
    from rich.progress import (BarColumn, Progress, SpinnerColumn, TaskProgressColumn, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    text = TextColumn("{task.description}", style="progress.description", markup=False)
    columns = ((SpinnerColumn(), text, TimeElapsedColumn()) if spinner
               else (text, BarColumn(), TaskProgressColumn(), TimeRemainingColumn()))
    return Progress(*columns, console=err.console, transient=True)


_FIGURE_FORMATS: Optional[list[str]] = None


def check_output(flag: str, path: Optional[Path], kind: str = "file") -> None:
    """Check, before any work, that an output path given to ``flag`` can be written; raise
    :class:`InvalidValueError` naming it if not.

    ``kind`` is ``"file"`` (its folder must exist and be writable, and the path must not be a folder),
    ``"figure"`` (a file whose suffix matplotlib writes: .png, .pdf, .svg...) or ``"folder"`` (a folder, made
    with its parents where missing: it must not be a file, nor lie under one).  ``None`` (not given) passes.

    Examples
    --------
    >>> check_output("--csv", Path("no-such-folder") / "r.csv")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: --csv 'no-such-folder/r.csv': the folder 'no-such-folder' does not exist
    """
    if path is None:
        return
    text = str(path)
    if not text.strip():
        raise InvalidValueError(f"{flag} is empty: give a {'folder' if kind == 'folder' else 'file'} name")
    if text == "." and kind != "folder":  # (also what Typer makes of "")
        raise InvalidValueError(f"{flag} is empty or '.': give a file name")
    if "\0" in text:
        raise InvalidValueError(f"{flag} {text!r} holds a NUL character, which no file name may")
    try:
        _check_output(flag, Path(path), text, kind)
    except OSError as exc:  # a name too long, a loop of links...
        raise InvalidValueError(f"{flag} {text!r} cannot be used: {exc.strerror or exc}") from None


def _check_output(flag: str, p: Path, text: str, kind: str) -> None:
    import os

    global _FIGURE_FORMATS
    suffix = p.suffix  # (the format is the name's, as given, even through a link)
    shown = repr(text)
    if p.is_symlink():  # the checks below are of where the link leads (writing follows it)
        real = Path(os.path.realpath(p))
        if real.is_symlink():
            raise InvalidValueError(f"{flag} {text!r} is a loop of links")
        if not real.exists() and kind == "folder":
            raise InvalidValueError(f"{flag} {text!r} is a link to {str(real)!r}, which does not exist")
        if not real.parent.is_dir():
            raise InvalidValueError(f"{flag} {text!r} is a link to {str(real)!r}, whose folder does not exist")
        p, shown = real, f"{text!r} (a link to {str(real)!r})"
    if kind == "folder":
        if p.exists() and not p.is_dir():
            raise InvalidValueError(f"{flag} {shown} is a file, not a folder")
        up = p
        while not up.exists():
            up = up.parent
        if not up.is_dir():
            raise InvalidValueError(f"{flag} {shown}: {str(up)!r} is a file, not a folder")
        if not os.access(up, os.W_OK | os.X_OK):
            raise InvalidValueError(f"{flag} {shown}: the folder {str(up)!r} is not writable")
        return
    if p.is_dir():
        raise InvalidValueError(f"{flag} {shown} is a folder: give a file name")
    folder = p.parent
    if not folder.exists():
        raise InvalidValueError(f"{flag} {shown}: the folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise InvalidValueError(f"{flag} {shown}: {str(folder)!r} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK) or p.exists() and not os.access(p, os.W_OK):
        raise InvalidValueError(f"{flag} {shown} cannot be written (no permission)")
    if kind == "figure" and suffix:
        if _FIGURE_FORMATS is None:
            from matplotlib.backend_bases import FigureCanvasBase

            _FIGURE_FORMATS = sorted(FigureCanvasBase.get_supported_filetypes())
        if suffix[1:].lower() not in _FIGURE_FORMATS:
            raise InvalidValueError(f"{flag} {shown}: {suffix!r} is not a figure format; use one of "
                                    f"{', '.join('.' + f for f in _FIGURE_FORMATS)}")


def fmt(x: Optional[float], digits: int = 4) -> str:
    """A number for a table, short at any magnitude: fixed point from ``10**-digits`` to a million, otherwise
    in exponent form (a delay of 1e300 is not printed as 300 digits, nor 1e-9 as zero); ``–`` for None or nan.

    Examples
    --------
    >>> fmt(0.368), fmt(1e300, 5), fmt(2e-9), fmt(None), fmt(float("inf"))
    ('0.3680', '1.00000e+300', '2.0000e-09', '–', 'inf')
    """
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    a = abs(float(x))
    if a == 0 or math.isinf(a) or 10.0 ** -digits <= a < 1e6:
        return f"{x:.{digits}f}"
    return f"{x:.{digits}e}"


def fmt_ci(ci: Any, digits: int = 4) -> str:
    """A confidence interval as text: ``a to b``, or ``no interval`` when the method gave none (``None``)."""
    return "no interval" if ci is None else f"{ci[0]:.{digits}f} to {ci[1]:.{digits}f}"


def ci_list(ci: Any) -> Optional[list[float]]:
    """A confidence interval for JSON: ``[a, b]``, or ``None`` (null) when there is none."""
    return None if ci is None else [float(ci[0]), float(ci[1])]


def print_rms(title: str, rows: list[tuple[str, float, Optional[float]]]) -> None:
    """A table of each log's RMS error beside its initial wander (``None`` where the log has none)."""
    from rich.table import Table

    table = Table(title=title)
    for col in ("log", "rms", "initial wander", "rms / wander"):
        table.add_column(col, justify="right")
    for file, rms, w in rows:
        table.add_row(file, f"{rms:.4g}", fmt(w), fmt(rms / w if w else None, 3))
    out.print(table)


def read_delay_trace(path: Path) -> Any:
    """``--delay-trace``: a CSV of ``t,delay`` (s), or a flight log with ``latency_ms``, chosen by the header."""
    import io

    from ..models.budget import MAX_FILE_BYTES, open_regular
    from ..simulate.varying import DelayTrace

    header: list[str] = []
    try:  # (a regular file only: a FIFO would block, /dev/zero never end; refused here before a byte is read)
        with io.TextIOWrapper(open_regular(path, "--delay-trace", MAX_FILE_BYTES), newline="",
                              encoding="utf-8-sig") as fh:
            header = [c.strip() for c in next(csv.reader(fh), [])]
    except (OSError, UnicodeDecodeError, csv.Error):
        return DelayTrace.from_csv(path)  # it says what is wrong with the file
    if not any(header):
        raise InvalidValueError(f"--delay-trace {str(path)!r} is empty: expected a header row t,delay (seconds) or "
                                "a flight log with t and latency_ms")
    if "delay" not in header and "latency_ms" in header:
        return DelayTrace.from_flight_log(path)
    if "delay" not in header:
        raise InvalidValueError(f"--delay-trace {str(path)!r} has no column 'delay' (s) or 'latency_ms' (a flight "
                                f"log); its header is {','.join(header)!r}")
    return DelayTrace.from_csv(path)


@contextlib.contextmanager
def run_until_stopped(duration: float) -> Iterator[Callable[[], None]]:
    """Run a service until Ctrl-C, SIGTERM, SIGHUP or ``duration`` s (0: no limit): yields ``wait()``, which
    returns then.

    The three signals end the run alike (the caller then prints its summary; exit status 0).  Their handlers,
    installed for the whole block (so that a signal while the service starts is not lost) and restored after it,
    only set a flag: a handler takes no lock (setting a ``threading.Event`` from a handler can deadlock, as it may
    run while the main thread holds that Event's own lock) and raises nothing mid-shutdown.  ``wait`` sleeps in
    ``select`` on the signals' wake-up descriptor (``signal.set_wakeup_fd``) until one comes or the time is up,
    without waking in between: a main thread that woke to poll would take the interpreter's lock from the
    service's threads at random moments, and on a busy machine hold it for a whole scheduler tick.  Outside the
    main thread no handler can be installed: there Ctrl-C alone ends ``wait``.

    Examples
    --------
    >>> with run_until_stopped(0.01) as wait:
    ...     wait()
    """
    import select
    import signal
    import socket
    import threading
    import time

    stop_signal: list[int] = []
    main_thread = threading.current_thread() is threading.main_thread()  # (signal handlers only go there)
    old = ({sig: signal.signal(sig, lambda signum, _frame: stop_signal.append(signum))
            for sig in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", signal.SIGTERM))}
           if main_thread else {})

    def wait() -> None:
        deadline = None if duration == 0 else time.monotonic() + duration
        rd, wr = socket.socketpair()
        for sock in (rd, wr):
            sock.setblocking(False)
        old_fd = signal.set_wakeup_fd(wr.fileno()) if main_thread else None
        try:
            while not stop_signal:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    break
                if select.select([rd], [], [], left)[0]:  # a signal came (its handler has run)
                    try:
                        rd.recv(64)
                    except OSError:
                        pass
        except KeyboardInterrupt:  # not from the handler above: only where it could not be installed
            pass
        finally:
            if old_fd is not None:
                signal.set_wakeup_fd(old_fd)
            rd.close()
            wr.close()

    try:
        yield wait
    finally:
        for sig, handler in old.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


def confirm_real(host: str, yes: bool) -> Optional[Callable[[], bool]]:
    import ipaddress

    try:
        loop = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loop = False
    if loop or yes:
        return None
    return lambda: typer.confirm(f"Take off the drone at {host}?", default=False)
