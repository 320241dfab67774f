"""The command line's persistent caches: a second run skips XLA compilation, and a
second `simulate` or `identify` also its tracing.

Every `jaxunilat` command compiles its solver afresh (1–3 s on 2 cores), more than most
commands then compute. JAX can keep compiled executables on disk
(`jax_compilation_cache_dir`), but still traces and lowers a program to find its key
(about 1 s for the event mode); `simulate`'s top-level calls and `identify`'s residuals
therefore also keep their executables under a key computed before tracing
(`jaxunilat.internal._executables`, in the `executables` folder). The command line turns
both on before anything compiles, in a user cache directory:

- `$JAXUNILAT_CACHE_DIR` if set, else `$XDG_CACHE_HOME/jaxunilat`, else
  `~/.cache/jaxunilat`;
- off with `JAXUNILAT_NO_CACHE=1` or the command line's `--no-cache`.

The cache is keyed by JAX on the program, the backend and the compile options, so a
stale entry is never used; deleting the directory is always safe. The Python API leaves
JAX's settings alone (`enable_compilation_cache()` is there for notebooks), and the
test suite runs without it.
"""

from __future__ import annotations

import os

from ..internal._executables import SUBDIR as EXECUTABLES_SUBDIR, enable_executable_cache

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


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache in `path` (default `cache_dir()`), and
    the executable cache (`simulate`, `identify`'s residuals) in its `executables` folder.

    Every compiled program is kept (no minimum compile time or size). Returns the
    directory, or None when `JAXUNILAT_NO_CACHE` is set or the directory cannot be made
    (a read-only home: the run goes on without a cache).
    """
    if cache_disabled():
        return None
    path = cache_dir() if path is None else os.path.abspath(path)
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    enable_executable_cache(os.path.join(path, EXECUTABLES_SUBDIR))
    return path
