"""The ``sonar-raster`` command line: the top-level parser, error handling and dispatch.

Each command lives in its own module (``render``, ``invert``, ``dataset``, ``track``,
``scenes``, ``doctor``) with ``add_parser(sub)`` and ``run(args) -> int``. Heavy modules
(moderngl, trimesh, OpenImageIO) load inside the commands, so ``--help`` answers at once. Bad
input ends with one line on stderr and exit status 2, with no traceback and no output file
left behind.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import io
import logging
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable
from typing import Any

from ..errors import InputWarning, SonarRasterError
from . import dataset, doctor, insert, invert, render, scenes, sensors, track

EXIT_BAD_INPUT = 2
#: Exit status when the reader of stdout went away (``sonar-raster sensors --json | head``):
#: 128 + SIGPIPE, as a command killed by the signal reports it.
EXIT_BROKEN_PIPE = 141

#: The commands in the order ``--help`` lists them.
COMMANDS = {
    "render": render,
    "invert": invert,
    "dataset": dataset,
    "insert": insert,
    "track": track,
    "scenes": scenes,
    "sensors": sensors,
    "doctor": doctor,
}


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``sonar-raster: error: ... (see --help)``, exit 2."""

    def error(self, message: str):  # type: ignore[override]
        print(f"sonar-raster: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sonar-raster",
        description="Side-scan sonar images from 3D scenes, rendered with headless OpenGL.",
    )
    parser.add_argument("--version", action="version", version=f"sonar-raster {_version()}")
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )
    for command in COMMANDS.values():
        command.add_parser(sub)
    for command_parser in sub.choices.values():
        if not any("--quiet" in action.option_strings for action in command_parser._actions):
            command_parser.add_argument(
                "-q", "--quiet", action="store_true", help="print nothing but warnings and errors"
            )
            command_parser.set_defaults(_silence_stdout=True)
    parser.set_defaults(_commands=dict(sub.choices))
    return parser


def _parse(argv: list[str] | None) -> argparse.Namespace:
    """The parsed command line; an unknown option is refused by its command's parser.

    argparse leaves unknown options to the top-level parser, whose error would point to
    ``sonar-raster --help``; here the command's own parser refuses them (``see 'sonar-raster
    render --help'``) and names the nearest option for a misspelt one.
    """
    args, extra = _parser().parse_known_args(argv)
    if extra:
        command = args._commands[args.command]
        known = [s for a in command._actions for s in a.option_strings if s.startswith("--")]
        hints = []
        for token in extra:
            if token.startswith("--"):
                close = difflib.get_close_matches(token.split("=", 1)[0], known, n=1)
                if close:
                    hints.append(f"{token}: did you mean {close[0]}?")
        hint = f" ({'; '.join(hints)})" if hints else ""
        command.error(f"unrecognized arguments: {' '.join(extra)}{hint}")
    return args


def _version() -> str:
    from .. import __version__

    return __version__


#: Warnings of these kinds concern the code, not the user's input: they stay warnings.
_DEVELOPER_WARNINGS = (DeprecationWarning, PendingDeprecationWarning, FutureWarning, ImportWarning)


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``timeout``, batch schedulers, ``kill``), raised where SIGINT would be."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise _Terminated


#: Seconds before an interrupt swallowed by a finalizer is sent again (the hook returns first).
REDELIVER_S = 0.01


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    SIGTERM is handled like Ctrl-C (temporary files removed, exit 143). A warning raised while a
    command runs (numeric overflow on absurd input, a library's complaint about a file) stops it
    with one error line, as bad input does, except warnings about the code itself
    (deprecations).
    """
    args = _parse(argv)
    logging.basicConfig(level=logging.WARNING, format="sonar-raster: %(message)s")
    restore = _install_signals()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            for category in _DEVELOPER_WARNINGS:
                warnings.simplefilter("default", category)
            warnings.simplefilter("always", InputWarning)
            warnings.showwarning = _show_warning(warnings.showwarning)
            if getattr(args, "_silence_stdout", False) and args.quiet:
                with contextlib.redirect_stdout(io.StringIO()):
                    return COMMANDS[args.command].run(args)
            code = COMMANDS[args.command].run(args)
            sys.stdout.flush()  # a closed pipe is found here, not at the interpreter's exit
            return code
    except BrokenPipeError:
        # the reader of stdout went away: stop quietly, and send what is left in the buffer
        # nowhere so that the interpreter's own flush at exit does not complain either
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except SonarRasterError as exc:
        print(f"sonar-raster: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Warning as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"sonar-raster: error: {message} ({type(exc).__name__}); check the input for "
              "absurd or non-finite values", file=sys.stderr)  # fmt: skip
        return EXIT_BAD_INPUT
    except _Terminated:
        print("sonar-raster: terminated (SIGTERM); nothing was written", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("sonar-raster: interrupted; nothing was written", file=sys.stderr)
        return 130
    finally:
        restore()


def _show_warning(fallback: Any) -> Any:
    """``warnings.showwarning`` that prints an :class:`InputWarning` as one line on stderr.

    Input warnings (a repaired model file, settings that image little) are for the user:
    ``sonar-raster: warning: <message>``, without the source location. Others go to
    ``fallback``.
    """

    def show(message, category, filename, lineno, file=None, line=None):  # type: ignore[no-untyped-def]
        if issubclass(category, InputWarning):
            text = " ".join(str(message).split())
            print(f"sonar-raster: warning: {text}", file=sys.stderr if file is None else file)
            return
        fallback(message, category, filename, lineno, file, line)

    return show


def _install_signals() -> Callable[[], None]:
    """Make SIGTERM raise like SIGINT, and a swallowed interrupt come back; return the undo.

    Python runs a signal's handler in the main thread at the next instruction, which may be
    inside a finalizer (``__del__``, a generator closed by the garbage collector); an exception
    raised there is printed as "Exception ignored" with a traceback, and the command runs on
    as if never stopped. The unraisable hook keeps that quiet and sends the signal again, so
    it lands where it can stop the command. Off the main thread nothing is installed.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    previous_hook = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        exc = unraisable.exc_value
        if not isinstance(exc, KeyboardInterrupt):
            previous_hook(unraisable)
            return
        again = signal.SIGTERM if isinstance(exc, _Terminated) else signal.SIGINT
        # from another thread: raised here, in the hook, it would be swallowed once more
        threading.Timer(REDELIVER_S, signal.raise_signal, (again,)).start()

    sys.unraisablehook = hook

    def restore() -> None:
        signal.signal(signal.SIGTERM, previous)
        sys.unraisablehook = previous_hook

    return restore


if __name__ == "__main__":
    sys.exit(main())
