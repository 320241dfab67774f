"""The `jaxunilat` command line: the shell that builds the parser and maps errors to exit codes.

    jaxunilat [--no-cache] [--debug] COMMAND ...

Exit codes: 0 success; 1 a run-time failure (the solver diverged or ran out of steps,
a file could not be written) or an internal error (a bug); 2 bad usage or input; 3 a fit
that did not converge or a recording refused as implausible (identify's commands);
130 interrupted. Every error is one line on stderr, `jaxunilat: error: ...`, with no
traceback and no usage dump; an internal error's line names the exception's type, and
`--debug` prints its traceback.

Commands: jaxunilat's own are listed in `_COMMANDS`, each `(name, module)` whose module
has `add_<name>(subparsers)`, imported only when the parser is built. Other packages
(identify) add theirs through the `jaxunilat.commands` entry points
(`jaxunilat.internal._cli` documents the protocol); jaxunilat never imports them by name.
"""

from __future__ import annotations

import logging
import os
import re
import sys

from ..internal._cli import COMMANDS_GROUP
from ..internal._errors import (
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_RUNTIME,
    EXIT_USAGE,
    PROG,
    InputError,
    RunError,
    UsageError,
)
from ._args import Parser, cli_spelling, command_flags

#: jaxunilat's own commands: (name, module holding `add_<name>(subparsers)`).
_COMMANDS = (
    ("simulate", "jaxunilat._cli._simulate"),
    ("sensitivity", "jaxunilat._cli._sensitivity"),
    ("reproduce", "jaxunilat._cli._reproduce"),
    ("bench", "jaxunilat._cli._bench"),
)

#: The order of `jaxunilat --help`'s command list; commands not named here come last,
#: in name order.
_HELP_ORDER = ("simulate", "identify", "import", "qualify", "sensitivity", "reproduce", "export", "bench")


def _own_command(module: str, name: str):
    """`add(subparsers)` that imports `module` only when the parser is built."""

    def add(subparsers) -> None:
        import importlib

        getattr(importlib.import_module(module), f"add_{name}")(subparsers)

    return add


def plugin_commands() -> dict:
    """The commands other packages register in the `jaxunilat.commands` entry-point group:
    `{name: register}`. One whose package is not installed is left out."""
    from importlib.metadata import entry_points

    found = {}
    for point in entry_points(group=COMMANDS_GROUP):
        try:
            found[point.name] = point.load()
        except ModuleNotFoundError as err:
            top = point.value.split(":")[0].split(".")[0]
            if err.name is None or err.name.split(".")[0] != top:
                raise  # the package is there but one of its imports is not: a bug to report
    return found


def _commands() -> list:
    """Every command's `register(subparsers)`, in `--help` order."""
    table = {name: _own_command(module, name) for name, module in _COMMANDS}
    for name, register in plugin_commands().items():
        table.setdefault(name, register)  # jaxunilat's own command keeps its name

    def rank(name):
        return (_HELP_ORDER.index(name), "") if name in _HELP_ORDER else (len(_HELP_ORDER), name)

    return [table[name] for name in sorted(table, key=rank)]


def build_parser() -> Parser:
    """The full argument parser (errors raise `UsageError`)."""
    from .. import __version__
    from ._compilation_cache import CACHE_DIR_ENV, NO_CACHE_ENV, cache_dir

    parser = Parser(
        prog=PROG,
        description="Differentiable simulation of systems with unilateral constraints [K90].",
        epilog=f"Compiled solvers are cached in {cache_dir()} (${CACHE_DIR_ENV} moves it; --no-cache or "
        f"{NO_CACHE_ENV}=1 turns it off): a second run skips compilation (simulate, identify: also tracing).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the persistent caches (compiled programs) for this run",
    )
    parser.add_argument("--debug", action="store_true", help="on an internal error, print the full traceback")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    for register in _commands():
        register(commands)
    return parser


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _fail(message: str, code: int) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return code


def _solver_line(err: RuntimeError) -> str | None:
    """The solver's own message (`jaxunilat.simulate: ...`) in a runtime error, wherever a
    wrapper put it (equinox prefixes its class name; JAX puts the traced stack first);
    None when it carries none."""
    ours = [m.group(0) for m in re.finditer(r"\bjaxunilat\.\w+: [^\n]*", str(err))]
    return ours[0] if ours else None


def _is_runtime_failure(err: RuntimeError) -> bool:
    """Whether `err` is a failure of a computation (equinox's or JAX's runtime error, or one
    carrying the solver's message), not a bug."""
    kinds = {"EquinoxRuntimeError", "JaxRuntimeError", "XlaRuntimeError"}
    return _solver_line(err) is not None or any(c.__name__ in kinds for c in type(err).__mro__)


def _report(err: BaseException, parser, args, debug: bool) -> int:
    """Print the one line for an exception that ended a command; its exit code."""
    flags = None if args is None else command_flags(parser, args)

    def spelled(text: str) -> str:
        return text if flags is None else cli_spelling(text, flags)

    if isinstance(err, (UsageError, InputError)):
        return _fail(spelled(str(err)), EXIT_USAGE)
    if isinstance(err, RunError):
        return _fail(str(err), EXIT_RUNTIME)
    if isinstance(err, RuntimeError) and _is_runtime_failure(err):
        line = _solver_line(err) or (str(err).splitlines() or [type(err).__name__])[0]
        return _fail(spelled(line), EXIT_RUNTIME)
    if debug:
        import traceback

        traceback.print_exception(err)
    hint = "" if debug else "; rerun with --debug for the traceback"
    return _fail(f"internal error: {type(err).__name__}: {err} (a bug in {PROG}{hint})", EXIT_INTERNAL)


EXIT_INTERRUPTED = 130


def _exit_on_interrupt():
    """Make Ctrl-C end the command at once, also while it waits inside a compilation
    or a compiled solve (where Python's own handler would only run once that returns,
    minutes or hours later): the signal wakes a watcher thread, which prints one line
    and exits with 130. Returns the function that removes the watcher again; a no-op
    outside the main thread (signals can only be handled there)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    try:
        old_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    except ValueError:  # e.g. a Python without signal support here
        os.close(read_fd)
        os.close(write_fd)
        return lambda: None
    # A Python handler must be set for the wakeup byte to be written; this one does
    # nothing, so that the main thread does not report the interrupt a second time.
    old_handler = signal.signal(signal.SIGINT, lambda signum, frame: None)

    def watch():
        while True:
            try:
                data = os.read(read_fd, 1)
            except OSError:
                return
            if not data:  # the write end was closed: the command finished
                return
            if data[0] == signal.SIGINT:
                os.write(2, f"{PROG}: error: interrupted\n".encode())
                os._exit(EXIT_INTERRUPTED)

    watcher = threading.Thread(target=watch, name="jaxunilat-interrupt", daemon=True)
    watcher.start()

    def remove():
        signal.signal(signal.SIGINT, old_handler)
        signal.set_wakeup_fd(old_fd)
        os.close(write_fd)
        watcher.join()
        os.close(read_fd)

    return remove


def main(argv: list[str] | None = None) -> int:
    """Run the command line with `argv` (default: `sys.argv[1:]`); return the exit code.

    Ctrl-C ends a command at once with one line, `jaxunilat: error: interrupted`, and
    exit code 130. Output files are written after the computation: an interrupted solve
    leaves none. Each file is moved into place whole (`internal.write_atomically`): an
    interrupt while one is being written leaves the earlier file of that name as it was,
    at worst with a hidden `.NAME.*.tmp` beside it.
    """
    from .._solver._loop_kernels import apply_on_import, user_flags

    # XLA_FLAGS as the user set it, without the loop-kernel option the import added.
    user_xla_flags = user_flags(os.environ.get("XLA_FLAGS"))
    # The import added it already, unless JAXUNILAT_NO_LOOP_KERNELS=1 opts out.
    apply_on_import()
    remove_watcher = _exit_on_interrupt()
    # A solver failure raised from inside a compiled run (throw=True) passes through a
    # host callback, which JAX also logs with a traceback; the error's one line suffices.
    callback_log = logging.getLogger("jax._src.callback")
    callback_level = callback_log.level
    callback_log.setLevel(logging.CRITICAL)
    words = sys.argv[1:] if argv is None else list(argv)
    parser = args = None
    try:
        from ._environment import check_environment

        # Before the parser: building it imports modules that may start JAX's backend
        # (not for help and the version, which compute nothing).
        if not {"-h", "--help", "--version"} & set(words):
            check_environment(user_xla_flags)
        parser = build_parser()
        args = parser.parse_args(words)
        if not args.no_cache:
            from ._compilation_cache import enable_compilation_cache

            enable_compilation_cache()
        return int(args.func(args))
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else EXIT_OK if exc.code is None else EXIT_USAGE
    except KeyboardInterrupt:
        return _fail("interrupted", EXIT_INTERRUPTED)
    except Exception as err:
        debug = args.debug if args is not None else "--debug" in words
        return _report(err, parser, args, debug)
    finally:
        callback_log.setLevel(callback_level)
        remove_watcher()
