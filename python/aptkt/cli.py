"""The ``aptkt`` command line. Each sub-command lives in :mod:`aptkt.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aptkt import __version__
from aptkt.errors import AptktError, Terminated

# One module per sub-command (or group); each defines ``register(subparsers)`` which adds its
# parser and sets ``func`` (called with the parsed arguments, returns an exit code).
COMMAND_MODULES: tuple[str, ...] = (
    "aptkt.commands.demo",
    "aptkt.commands.skin",
    "aptkt.commands.dataset",
    "aptkt.commands.prior",
    "aptkt.commands.recognise",
    "aptkt.commands.collect",
    "aptkt.commands.learn",
    "aptkt.commands.reproduce",
    "aptkt.commands.benchmark",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="aptkt",
        description="Active Prior Tactile Knowledge Transfer: tactile object learning with a robot skin.",
    )
    parser.add_argument("--version", action="version", version=f"aptkt {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    _mark_parsers(parser)
    return parser


def _mark_parsers(parser: argparse.ArgumentParser) -> None:
    """Each (sub-)command's parser records itself in the arguments it parses, so that an
    unknown option is reported by the command it was given to (argparse leaves that to the
    top-level parser: `aptkt: error: unrecognized arguments`)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                child.set_defaults(_usage_parser=child)
                _mark_parsers(child)


def _version() -> str:
    return __version__


def _label(args: argparse.Namespace) -> str:
    """``aptkt dataset generate``: the command as typed, for messages."""
    words = [args.command]
    for key, value in vars(args).items():
        if key.endswith("_command") and isinstance(value, str):
            words.append(value)
    return "aptkt " + " ".join(words)


def _missing_dirs(args: argparse.Namespace) -> list[Path]:
    """The output paths (and their parent directories) that do not exist yet, deepest first:
    those a failed command may have created as directories and must not leave behind empty."""
    missing: list[Path] = []
    for key in ("output", "record"):
        value = getattr(args, key, None)
        if not isinstance(value, (str, Path)):
            continue
        path = Path(value).absolute()
        for p in (path, *path.parents):
            # (os.path: a name the system refuses, too long say, is an error for the command's
            # own checks to report, not a traceback here.)
            if os.path.lexists(p):
                break
            missing.append(p)
    return sorted(set(missing), key=lambda p: len(p.parts), reverse=True)


def _remove_empty(dirs: list[Path]) -> None:
    for d in dirs:
        try:
            d.rmdir()  # only an empty directory
        except OSError:
            pass


#: A reader that left (``aptkt learn ... | head -1``): the exit code of a program stopped by
#: SIGPIPE, 128 + 13, as a shell reports it.
EXIT_CLOSED_PIPE = 141


class _ClosedPipeGuard:
    """Standard output that, once its reader has gone, drops what is written instead of
    raising: the command finishes its work and keeps its results on disk, rather than dying at
    its next progress line."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.closed = False

    def write(self, text: str) -> int:
        if not self.closed:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._close()
        return len(text)

    def flush(self) -> None:
        if not self.closed:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._close()

    def _close(self) -> None:
        self.closed = True
        # What the stream still buffers would fail again when Python flushes it at exit (and
        # print "Exception ignored ..."): its descriptor now leads nowhere.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):
            pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


# How many calls of the command's unraisable hook are running (see _keep_swallowed_signals).
_hook_depth = 0


def _stop_the_command(signum: int, frame: Any) -> None:
    if _hook_depth:
        # Raised inside the hook, the exception would be swallowed as well: signal again once
        # the hook has returned.
        _signal_again_soon(signum)
        return
    if signum == signal.SIGTERM:
        raise Terminated(f"signal {signal.Signals(signum).name}")
    signal.default_int_handler(signum, frame)  # (Ctrl-C: KeyboardInterrupt, as Python raises it)


def _signal_again_soon(signum: int) -> None:
    # Sent by another thread once the main thread has left the hook (starting that thread
    # alone gives the main thread's handler a chance to run, still inside it); sent to the
    # main thread, so that a blocking call it makes meanwhile is interrupted.
    main_thread = threading.main_thread().ident

    def send() -> None:
        while _hook_depth:
            time.sleep(0.001)
        if main_thread is not None:
            signal.pthread_kill(main_thread, signum)

    try:
        threading.Thread(target=send, name="aptkt-signal-again", daemon=True).start()
    except RuntimeError:  # (the interpreter is shutting down: the command is over)
        pass


def _keep_swallowed_signals(fallback: Any) -> Any:
    """A ``sys.unraisablehook`` for the time a command runs. Python runs a signal's handler
    wherever the main thread is; in a garbage collector's callback or a ``__del__`` the
    handler's exception cannot propagate, and Python prints "Exception ignored" and goes on:
    the command would not stop (seen under load: a SIGTERM during a weakref callback, and the
    process ran on). Such a signal is sent again, to be handled in the command's own code."""

    def hook(unraisable: Any) -> None:
        global _hook_depth
        _hook_depth += 1
        try:
            exc = unraisable.exc_value
            if isinstance(exc, KeyboardInterrupt):
                _signal_again_soon(signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)
            else:
                fallback(unraisable)
        finally:
            _hook_depth -= 1

    return hook


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    command_parser = vars(args).pop("_usage_parser", parser)
    if unknown:  # usage and one `aptkt <command>: error:` line, exit code 2 (argparse's rule)
        command_parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    label = _label(args)
    created = _missing_dirs(args)
    code = 1
    previous: dict[int, Any] = {}
    unraisablehook = sys.unraisablehook
    stdout = sys.stdout
    guard = _ClosedPipeGuard(stdout)
    sys.stdout = guard
    try:
        if threading.current_thread() is threading.main_thread():
            # SIGTERM takes the path of Ctrl-C: every command stops cleanly (a robot command
            # stops and retracts the arm and keeps the partial recording) instead of dying on
            # the spot. Ctrl-C raises KeyboardInterrupt again, whatever start-up set
            # (aptkt._entry). A signal the caller ignores stays ignored (a shell's background
            # job ignores Ctrl-C). Set inside the try: a signal right after is handled below.
            sys.unraisablehook = _keep_swallowed_signals(unraisablehook)
            for signum in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(signum) != signal.SIG_IGN:
                    previous[signum] = signal.signal(signum, _stop_the_command)
        code = int(args.func(args) or 0)
        if guard.closed and code == 0:
            code = EXIT_CLOSED_PIPE
        return code
    except AptktError as exc:
        print(f"{label}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        # The system refused a file operation the checks up front could not foresee (a disk
        # full, a file removed meanwhile): one line naming the file, not a traceback.
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"{label}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        # (A trial's interruption carries the signal's as its cause.)
        terminated = isinstance(exc, Terminated) or isinstance(exc.__cause__, Terminated)
        notes = "; ".join(getattr(exc, "__notes__", ()))
        print(
            f"{label}: {'terminated (SIGTERM)' if terminated else 'interrupted'}"
            + (f": {notes}" if notes else ""),
            file=sys.stderr,
        )
        code = 143 if terminated else 130
        return code
    finally:
        guard.flush()
        if guard.closed and code == 0:
            code = EXIT_CLOSED_PIPE
        sys.stdout = stdout
        sys.unraisablehook = unraisablehook
        for number, before in previous.items():
            if before is not None:  # (None: not set from Python; nothing to put back)
                signal.signal(number, before)
        if code != 0:
            _remove_empty(created)


if __name__ == "__main__":
    sys.exit(main())
