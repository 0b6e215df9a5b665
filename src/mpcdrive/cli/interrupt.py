"""Ctrl-C and SIGTERM for the command line, from its first statement to its last.

:func:`install` runs first in :func:`mpcdrive.cli.main`, before anything heavy is imported
(numpy, numba, matplotlib, the commands), so a signal at any moment of a command gets the same
answer: exit code 130 and one line on stderr, with no partial output left behind.

The handler does not raise into the code it interrupted. A signal can land anywhere: in an
extension module's import, inside numba's compiler or an LLVM callback, in code that drops
exceptions; an exception unwinding through such code can be lost (the command goes on) or leave
C state that aborts the interpreter later. The handler instead removes every temporary output
this process has not committed (:func:`mpcdrive.io.atomic.discard_unfinished`), restores the
terminal a progress bar had, writes the line with one system call and ends the process with
``os._exit(130)``, without running the interpreter's shutdown.

Where stopping needs the code's own unwinding -- a pool of worker processes to stop, a cluster to
cancel -- that code installs, for its block, handlers that raise ``KeyboardInterrupt``
(:func:`mpcdrive.sweep.runner.run_parallel`), and :func:`mpcdrive.cli.main` answers the
exception with the same code and line. This module imports nothing beyond the standard library.
"""

from __future__ import annotations

import os
import signal
import sys

MESSAGE = "mpcdrive: interrupted; no partial output was kept"

#: a progress bar is drawn on a terminal (it hides the cursor): the handler shows it again
progress_shown = False


def _restore_terminal() -> None:
    if not progress_shown:
        return
    try:
        if os.isatty(2):
            os.write(2, b"\r\x1b[2K\x1b[?25h")  # clear the bar's line, show the cursor
    except OSError:
        pass


def exit_interrupted(signum: int | None = None, frame=None) -> None:
    """End the process now: exit code 130, :data:`MESSAGE` on stderr, nothing half-written left.

    The signal handler of the command line (``signum``, ``frame`` as :mod:`signal` passes them),
    and, with no arguments, the end of the command once an interrupt reached it as
    ``KeyboardInterrupt`` and unwound it."""
    for sig in (signal.SIGINT, signal.SIGTERM):  # a second signal during the cleanup is not another end
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (OSError, ValueError):
            pass
    atomic = sys.modules.get("mpcdrive.io.atomic")  # (never imported here: the import lock may be held)
    if atomic is not None:
        try:
            atomic.discard_unfinished()
        except BaseException:
            pass
    _restore_terminal()
    mp_util = sys.modules.get("multiprocessing.util")
    if signum is None and mp_util is not None:
        # unwound to the top (the worker pool stopped): what the interpreter's exit would run for
        # multiprocessing -- release the pool's semaphores, else its resource tracker warns of
        # leaked ones after the message
        try:
            mp_util._exit_function()
        except BaseException:
            pass
    for stream in (sys.stdout, sys.stderr):  # what the command printed before (not reentrant: may fail)
        try:
            stream.flush()
        except BaseException:
            pass
    try:
        os.write(2, (MESSAGE + "\n").encode())
    except OSError:
        pass
    os._exit(130)


def install() -> None:
    """Make SIGINT (unless the process was started ignoring it, as a shell's background job is)
    and SIGTERM end the command through :func:`exit_interrupted`."""
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, exit_interrupted)
    signal.signal(signal.SIGTERM, exit_interrupted)
