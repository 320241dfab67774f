"""The `jaxunilat` command line: the shell that builds the parser and maps errors to exit codes.

    jaxunilat [--no-cache] [--debug] COMMAND ... [--no-cache] [--debug]

The global flags (`_args.GLOBAL_FLAGS`) mean the same before the command and after it,
at any level (`jaxunilat simulate ball --no-cache`); `--version` too.

Exit codes: 0 success; 1 a run-time failure (the solver diverged or ran out of steps,
a file or the standard output could not be written) or an internal error (a bug); 2 bad
usage or input; 3 a fit that did not converge or a recording refused as implausible
(identify's commands); 130 interrupted; 141 (128 + SIGPIPE) the reader of the standard
output went away (`jaxunilat ... | head`), without a message, as Unix tools end there.
Every error is one line on stderr, `jaxunilat: error: ...`, with no traceback and no
usage dump; control characters in it (a file name's newline or terminal escape) are
shown escaped and numbers of more than 16 digits shortened (`internal._text`). An
internal error's line names the exception's type, and `--debug` prints its traceback.

Commands: every command is one line of `COMMANDS`, `(name, "module:function")`, in
`--help` order, where `function(subparsers)` adds the command's parser
(`jaxunilat._internal._cli` documents what a command's module provides). The identify
commands live in the subpackage `jaxunilat.identify`; the engine never imports it. A
command's module is imported only when the command line names it: `jaxunilat --help`
lists each command with the help line that its function passes as a string literal
(read from the source, `written_summary`), so that `--help` and `--version` import no
command, and `jaxunilat simulate ...` nothing of identify.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import os
import re
import sys

from .._internal._errors import (
    EXIT_BROKEN_PIPE,
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_RUNTIME,
    EXIT_USAGE,
    PROG,
    InputError,
    RunError,
    UsageError,
)
from .._internal._text import bounded_numbers, printable
from ._args import Parser, add_global_flags, cli_spelling, command_flags, repeat_global_flags

#: Every command: (name, "module:function" adding its parser to the subparsers), in the
#: order of `jaxunilat --help`'s command list.
COMMANDS = (
    ("simulate", "jaxunilat._cli._simulate:add_simulate"),
    ("identify", "jaxunilat.identify._cli._identify:register"),
    ("import", "jaxunilat.identify._cli._import:register"),
    ("qualify", "jaxunilat.identify._cli._qualify:register"),
    ("sensitivity", "jaxunilat._cli._sensitivity:add_sensitivity"),
    ("reproduce", "jaxunilat._cli._reproduce:add_reproduce"),
    ("export", "jaxunilat.identify._cli._export:register"),
    ("bench", "jaxunilat._cli._bench:add_bench"),
)


def _loaded(target: str):
    """The function `target` ("module:function"), its module imported."""
    import pkgutil

    return pkgutil.resolve_name(target)


def written_summary(name: str, target: str) -> str | None:
    """The help line that function `target` ("module:function") gives command `name`,
    read from the source of its module without importing it: the string literal `help`
    of the `add_parser(NAME, help="...")` call in the function. None where the source does
    not say it so plainly (no such call, aliases, a computed help) or cannot be read; the
    command is then loaded to list it."""
    import ast
    from importlib.util import find_spec

    module, _, attr = target.partition(":")
    names = module.strip().split(".")
    try:
        spec = find_spec(names[0])  # a top-level name: found, not imported
        for end in range(2, len(names) + 1):
            spec = _found(".".join(names[:end]), spec.submodule_search_locations)
        with open(spec.origin, encoding="utf-8") as f:
            tree = ast.parse(f.read())
    except (AttributeError, ImportError, OSError, SyntaxError, TypeError, ValueError):
        return None
    body = [node for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == attr.strip()]
    for node in ast.walk(body[0]) if body else ():
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
            continue
        first = node.args[0] if node.func.attr == "add_parser" and node.args else None
        if isinstance(first, ast.Constant) and first.value == name:
            keywords = {k.arg: k.value for k in node.keywords}
            text = keywords.get("help")
            plain = "aliases" not in keywords and None not in keywords and isinstance(text, ast.Constant)
            return text.value if plain and isinstance(text.value, str) else None
    return None


def _found(name: str, path: list[str]):
    """The spec of submodule `name` whose package's search path is `path`, as the import
    system's finders give it, without importing the package (an editable install maps
    `jaxunilat.identify` to the repository's identify/ folder through its own finder)."""
    import sys

    for finder in sys.meta_path:
        spec = finder.find_spec(name, path) if hasattr(finder, "find_spec") else None
        if spec is not None:
            return spec
    return None


def _lazy(target: str):
    """`register(subparsers)` that imports `target`'s module only when called."""

    def register(subparsers) -> None:
        _loaded(target)(subparsers)

    return register


def _commands(lazy: bool = False) -> list:
    """Every command as `(name, register, summary)`, in `--help` order. `summary` is None
    for a command to register now; with `lazy`, a command whose help line its source
    gives (`written_summary`) has it, to be registered only if chosen."""
    listed = []
    for name, target in COMMANDS:
        summary = written_summary(name, target) if lazy else None
        listed.append((name, _loaded(target) if summary is None else _lazy(target), summary))
    return listed


class _Commands(argparse._SubParsersAction):
    """The subparsers of the commands, where a command can wait unloaded: listed with its
    help line (`jaxunilat --help`), and registered (its package imported) only when the
    command line names it."""

    def __init__(self, *args, version: str, **kwargs):
        super().__init__(*args, **kwargs)
        self.version = version
        self.waiting: dict = {}

    def add_command(self, name: str, register, summary: str | None) -> None:
        """Register the command now (`summary` None), else list it until it is chosen."""
        if summary is None:
            register(self)
            if name in self.choices:
                repeat_global_flags(self.choices[name], self.version)
        else:
            self.add_parser(name, help=summary, add_help=False)
            self.waiting[name] = register

    def _load(self, name: str) -> None:
        """Replace the waiting command `name` by its parser, at the same place in `--help`."""
        register = self.waiting.pop(name)
        del self._name_parser_map[name]
        place = next(i for i, a in enumerate(self._choices_actions) if a.dest == name)
        del self._choices_actions[place]
        self.add_command(name, register, None)
        moved = [a for a in self._choices_actions[place:] if a.dest == name]
        for action in moved:
            self._choices_actions.remove(action)
            self._choices_actions.insert(place, action)

    def __call__(self, parser, namespace, values, option_string=None):
        if values and values[0] in self.waiting:
            self._load(values[0])
        super().__call__(parser, namespace, values, option_string)


def build_parser(lazy: bool = False) -> Parser:
    """The full argument parser (errors raise `UsageError`). With `lazy`, a command's module
    is imported only when the command line names it: `jaxunilat --help` and `--version`
    import none, and `jaxunilat simulate ...` nothing of identify."""
    from .. import __version__
    from ._compilation_cache import CACHE_DIR_ENV, NO_CACHE_ENV, cache_dir

    version = f"{PROG} {__version__}"
    parser = Parser(
        prog=PROG,
        description="Differentiable simulation of systems with unilateral constraints [K90].",
        epilog=f"Compiled solvers are cached in {cache_dir()} (${CACHE_DIR_ENV} moves it; --no-cache or "
        f"{NO_CACHE_ENV}=1 turns it off): a second run skips compilation (simulate, identify: also tracing). "
        "The options above are also accepted after the command.",
    )
    add_global_flags(parser, version)
    commands = parser.add_subparsers(
        dest="command",
        metavar="COMMAND",
        required=True,
        parser_class=Parser,
        action=_Commands,
        version=version,
    )
    for name, register, summary in _commands(lazy):
        commands.add_command(name, register, summary)
    return parser


def _one_line(text: str) -> str:
    """`text` as one line: its line breaks and runs of white space as one space, other
    control characters escaped, numbers of more than 16 digits shortened."""
    return bounded_numbers(printable(" ".join(str(text).split())))


def _fail(message: str, code: int) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return code


def _solver_line(err: BaseException) -> str | None:
    """The solver's own message (`jaxunilat.simulate: ...`) in a runtime error, wherever a
    wrapper put it (equinox prefixes its class name; JAX puts the traced stack first);
    None when it carries none."""
    ours = [m.group(0) for m in re.finditer(r"\bjaxunilat\.\w+: [^\n]*", str(err))]
    return ours[0] if ours else None


def _is_runtime_failure(err: BaseException) -> bool:
    """Whether `err` is a failure of a computation (equinox's or JAX's runtime error, one
    carrying the solver's message, or the `ValueError` of JAX's fast path for a failed
    host callback), not a bug."""
    if isinstance(err, ValueError):
        return "_EquinoxRuntimeError: " in str(err)
    kinds = {"EquinoxRuntimeError", "JaxRuntimeError", "XlaRuntimeError"}
    return _solver_line(err) is not None or any(c.__name__ in kinds for c in type(err).__mro__)


def _runtime_line(err: BaseException) -> str:
    """The one line of a runtime failure: the solver's message, else equinox's message
    without its advice, else the error's first line."""
    line = _solver_line(err)
    if line is None:
        found = re.search(r"EquinoxRuntimeError: ([^\n]+)", str(err))
        line = found.group(1) if found else (str(err).splitlines() or [type(err).__name__])[0]
    return line


class _Stdout:
    """The standard output while a command runs: the same stream, remembering the
    `OSError` that a write or flush of it raised (a full disk, a closed pipe), also one
    that the code printing swallowed (argparse's `--version` does), so that `main` tells
    it from a failure to write a file."""

    def __init__(self, stream):
        self.stream = stream
        self.failure: OSError | None = None

    def _watch(self, method: str, *args):
        try:
            return getattr(self.stream, method)(*args)
        except OSError as err:
            self.failure = err
            raise

    def write(self, text):
        return self._watch("write", text)

    def writelines(self, lines):
        return self._watch("writelines", lines)

    def flush(self):
        return self._watch("flush")

    def __getattr__(self, name):
        return getattr(self.stream, name)


def _stdout_failure() -> OSError | None:
    """The failure of the standard output so far, flushing it first; None if it took
    everything (or is not watched)."""
    out = sys.stdout
    if not isinstance(out, _Stdout):
        return None
    try:
        out.flush()
    except OSError:
        pass
    except ValueError:  # closed
        return out.failure
    return out.failure


def _stdout_failed(err: OSError) -> int:
    """End a command whose output failed: a reader that went away (EPIPE: of the standard
    output, also of `--out /dev/stdout` or a FIFO) ends it quietly with 128 + SIGPIPE, as
    Unix tools end there; any other failure of the standard output (a full disk:
    `> /dev/full`) is one line naming stdout, exit 1. When the process's own stdout failed,
    what is left in its buffer is dropped (its descriptor is pointed at the null device),
    so that Python's exit adds nothing."""
    stream = getattr(sys.stdout, "stream", sys.stdout)
    if stream is sys.__stdout__ and stream is not None and _stdout_failure() is not None:
        try:
            fd = stream.fileno()
            null = os.open(os.devnull, os.O_WRONLY)
        except (OSError, ValueError):  # no descriptor
            pass
        else:
            os.dup2(null, fd)
            os.close(null)
    if isinstance(err, BrokenPipeError) or err.errno == errno.EPIPE:
        return EXIT_BROKEN_PIPE
    reason = f"[Errno {err.errno}] {err.strerror}" if err.errno else str(err)
    return _fail(f"stdout: cannot write: {reason}", EXIT_RUNTIME)


def _flushed(code: int) -> int:
    """`code`, once the standard output took everything printed (else `_stdout_failed`)."""
    failure = _stdout_failure()
    return code if failure is None else _stdout_failed(failure)


def _report(err: BaseException, parser, args, debug: bool) -> int:
    """Print the one line for an exception that ended a command; its exit code."""
    flags = None if args is None else command_flags(parser, args)

    def spelled(text: str) -> str:
        return text if flags is None else cli_spelling(text, flags)

    if isinstance(err, (UsageError, InputError)):
        return _fail(spelled(str(err)), EXIT_USAGE)
    if isinstance(err, RunError):
        return _fail(str(err), EXIT_RUNTIME)
    if isinstance(err, BrokenPipeError) or (isinstance(err, OSError) and err is _stdout_failure()):
        return _stdout_failed(err)
    if isinstance(err, (RuntimeError, ValueError)) and _is_runtime_failure(err):
        return _fail(spelled(_runtime_line(err)), EXIT_RUNTIME)
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
    at worst with a hidden `.jxu-*.tmp` beside it.
    """
    from .._internal._loop_kernels import apply_on_import, user_flags

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
    stdout = sys.stdout = _Stdout(sys.stdout)
    try:
        from ._environment import check_environment

        # Before the parser: building it imports modules that may start JAX's backend
        # (not for help and the version, which compute nothing).
        if not {"-h", "--help", "--version"} & set(words):
            check_environment(user_xla_flags)
        parser = build_parser(lazy=True)
        args = parser.parse_args(words)
        if not args.no_cache:
            from ._compilation_cache import enable_compilation_cache

            enable_compilation_cache()
        # Latency-bound commands run on the host CPU where the default backend is an
        # accelerator (`_internal.on_host`); the bench measures what Python users get.
        from .._internal._placement import on_host

        placement = contextlib.nullcontext() if args.command == "bench" else on_host()
        with placement:
            return _flushed(int(args.func(args)))
    except SystemExit as exc:  # --help, --version
        return _flushed(
            exc.code if isinstance(exc.code, int) else EXIT_OK if exc.code is None else EXIT_USAGE
        )
    except KeyboardInterrupt:
        return _fail("interrupted", EXIT_INTERRUPTED)
    except Exception as err:
        debug = args.debug if args is not None else "--debug" in words
        return _report(err, parser, args, debug)
    finally:
        if sys.stdout is stdout:
            sys.stdout = stdout.stream
        callback_log.setLevel(callback_level)
        remove_watcher()
