"""Command-line interface: the only place that parses arguments, converts units for people,
and prints. Exit codes: 0 done, 2 bad input (one line on stderr: file, field, problem), 1 other
failures.

The commands live by kind, each module registering its own on :data:`app`: ``drive`` (``list``,
``run``), ``studies`` (``reproduce``, ``compare-avoidance``, ``bench``, ``compare-models``) and
``batch`` (``sweep``, ``commonroad``); ``common`` holds the app and what the commands share, this
module the console entry point :func:`main` (also ``python -m mpcdrive.cli``).

Importing this module imports nothing but the standard library and :mod:`.interrupt`: the console
script and ``python -m mpcdrive`` import it before :func:`main` runs, and :func:`main` installs
the signal handlers before the commands (and numpy, numba, typer) are imported. ``app``,
``BadInput`` and ``OutputAbandoned`` are loaded on first use."""

from __future__ import annotations

import sys

from . import interrupt

__all__ = ["BadInput", "OutputAbandoned", "app", "main"]


def __getattr__(name: str):
    if name in __all__:
        return getattr(_commands(), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _commands():
    """The app with every command registered (imports the commands and what they need)."""
    from . import common

    # the commands, registered on app in the order `mpcdrive --help` lists them
    from . import drive, studies, batch  # noqa: F401

    return common


def _log_to_stderr() -> None:
    """The library's INFO lines (logger ``mpcdrive``: e.g. the one-time compile notice) go to
    stderr as ``mpcdrive: <message>``."""
    import logging

    log = logging.getLogger("mpcdrive")
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("mpcdrive: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
        log.propagate = False


def _scenario_warnings_as_lines() -> None:
    """Print each :class:`~mpcdrive.types.ScenarioWarning` as one line on stderr,
    ``mpcdrive: warning: <file>: <field>: <problem>`` (other warnings as Python prints them)."""
    import warnings

    import typer

    from ..types import ScenarioWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, ScenarioWarning):
            typer.echo(f"mpcdrive: warning: {' '.join(str(message).split())}", err=True)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def main() -> None:
    """Console-script entry point. Exit codes: 0 done, 1 other failures, 2 bad input, 3 a
    ``run --check`` that collided, left the road or missed its goal, 130 interrupted (Ctrl-C or
    SIGTERM at any moment, :mod:`.interrupt`)."""
    interrupt.install()  # first: before the imports below, which take seconds on a loaded machine
    try:
        _main()
    except KeyboardInterrupt:  # raised where stopping needs unwinding (worker pools), or by OSQP
        interrupt.exit_interrupted()


def _main() -> None:
    import typer

    from ..io.atomic import OutputPathError

    common = _commands()
    app, BadInput, OutputAbandoned = common.app, common.BadInput, common.OutputAbandoned
    _log_to_stderr()
    _scenario_warnings_as_lines()
    if len(sys.argv) == 1:  # a bare `mpcdrive` shows the help as it is, not folded into a usage error
        sys.argv.append("--help")
    try:
        rc = app(standalone_mode=False)
        if rc == 130:  # typer turns Ctrl-C into a returned exit code 130 in this mode
            raise KeyboardInterrupt
        if isinstance(rc, int) and not isinstance(rc, bool) and rc:
            sys.exit(rc)
    except BadInput as e:
        typer.echo(f"mpcdrive: {e}", err=True)
        sys.exit(2)
    except FileExistsError as e:
        typer.echo(f"mpcdrive: --out: {e}", err=True)
        sys.exit(2)
    except OutputPathError as e:  # an output file or folder that cannot be made where it was asked for
        typer.echo(f"mpcdrive: {e}", err=True)
        sys.exit(2)
    except OutputAbandoned as e:
        typer.echo(f"mpcdrive: error: {e}", err=True)
        sys.exit(1)
    except typer.Exit as e:
        sys.exit(e.exit_code)
    except Exception as e:
        fmt = getattr(e, "format_message", None)
        code = getattr(e, "exit_code", None)
        if callable(fmt) and isinstance(code, int):  # usage errors carry their own code (2)
            ctx = getattr(e, "ctx", None)
            where = ctx.command_path if ctx is not None else "mpcdrive"
            typer.echo(f"{where}: {' '.join(fmt().split())}", err=True)
            sys.exit(code)
        if type(e).__name__ == "Abort":  # click's answer to a KeyboardInterrupt it caught
            interrupt.exit_interrupted()
        typer.echo(f"mpcdrive: error: {type(e).__name__}: {e}", err=True)
        sys.exit(1)
