"""The persistent caches: a second run skips XLA compilation, and a second `simulate` or
`identify` command also its tracing.

Every `jaxunilat` command compiles its solver afresh (1–3 s on 2 cores), more than most
commands then compute. JAX can keep compiled executables on disk
(`jax_compilation_cache_dir`), but still traces and lowers a program to find its key
(about 1 s for the event mode); `simulate`'s top-level calls and `identify`'s residuals
therefore also keep their executables under a key computed before tracing
(`jaxunilat._internal._executables`, in the `executables` folder). The command line turns
both on before anything compiles, in a user cache directory:

- `$JAXUNILAT_CACHE_DIR` if set, else `$XDG_CACHE_HOME/jaxunilat`, else
  `~/.cache/jaxunilat`;
- off with `JAXUNILAT_NO_CACHE=1` or the command line's `--no-cache`.

The cache is keyed by JAX on the program, the backend and the compile options, so a
stale entry is never used; deleting the directory is always safe.

Trust: a cache directory holds programs that the next command runs, so it must be yours
alone. The directory and its `executables` folder are created 0700; one that another
user owns, or that has a group or other write bit, is refused (as ssh refuses such a
`~/.ssh`), and so is one this process cannot write to (a read-only home). A refused
directory turns both caches off for the run, which says so in one line on stderr
(`jaxunilat: warning: ...`, once per process) and otherwise goes on as with `--no-cache`.
The check protects JAX's own cache too, whose entries are compiled programs although
not pickles; the executables are besides authenticated (an HMAC under a key of yours:
`jaxunilat._internal._executables`). The Python API leaves JAX's settings alone unless asked:
`jaxunilat.enable_compilation_cache()` turns the
same caches on for a script or notebook, so that its second run skips XLA compilation
(`jax.grad` of an event-mode solve compiles for ~20 s on 2 cores). The test suite runs
without them.
"""

from __future__ import annotations

import os
import sys

from ._text import printable

#: Environment variables: the directory, and the opt-out.
CACHE_DIR_ENV = "JAXUNILAT_CACHE_DIR"
NO_CACHE_ENV = "JAXUNILAT_NO_CACHE"


def cache_dir() -> str:
    """Where the command line's compilation cache lives (see the module docstring)."""
    explicit = os.environ.get(CACHE_DIR_ENV)
    if explicit:
        return os.path.abspath(os.path.expanduser(explicit))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(os.path.abspath(base), "jaxunilat")


def cache_disabled() -> bool:
    """Whether `JAXUNILAT_NO_CACHE` asks for no cache (any value but '', '0', 'false', 'no')."""
    return os.environ.get(NO_CACHE_ENV, "").strip().lower() not in ("", "0", "false", "no")


#: The directories already refused in this process (each is reported once).
_REPORTED: set[str] = set()


def _refuse(path: str, why: str) -> None:
    """Say once per process and directory, in one line on stderr, why `path` is not used."""
    if path in _REPORTED:
        return
    _REPORTED.add(path)
    if "key file" in why:
        fix = f"remove {path} (its programs are compiled again), set ${CACHE_DIR_ENV} elsewhere, or pass --no-cache"
    elif "others can write" in why:
        fix = f"run 'chmod 700 {path}', set ${CACHE_DIR_ENV} to a directory of your own, or pass --no-cache"
    else:
        fix = f"set ${CACHE_DIR_ENV} to a writable directory of your own, or pass --no-cache"
    line = f"not using the cache directory {path}: {why}; running without the cache ({fix})"
    print(f"jaxunilat: warning: {printable(line)}", file=sys.stderr)


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache in `path` (default `cache_dir()`:
    `$JAXUNILAT_CACHE_DIR`, else `$XDG_CACHE_HOME/jaxunilat`, else `~/.cache/jaxunilat`),
    and the executable cache (`simulate` with `throw=False`, `identify`'s residuals) in its
    `executables` folder. Public as `jaxunilat.enable_compilation_cache`: call it once, before
    the first computation, in a script or notebook whose programs take long to compile.

    Every compiled program is kept (no minimum compile time or size). Returns the
    directory, or None when `JAXUNILAT_NO_CACHE` is set, or when the directory or its
    `executables` folder cannot be made, written to, or trusted (see the module
    docstring): the run then goes on without a cache, and says why in one line on stderr.
    """
    if cache_disabled():
        return None
    from ._executables import (
        SUBDIR as EXECUTABLES_SUBDIR,
        ExecutableCache,
        private_directory,
        set_executable_cache,
    )

    path = cache_dir() if path is None else os.path.abspath(path)
    why = private_directory(path)
    if why is not None:
        _refuse(path, why)
        return None
    executables = ExecutableCache(os.path.join(path, EXECUTABLES_SUBDIR))
    why = executables.prepare()
    if why is not None:
        _refuse(executables.path, why)
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    set_executable_cache(executables)
    return path
