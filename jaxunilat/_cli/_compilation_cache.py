"""The command line's caches: `jaxunilat._internal._compilation_cache` (shared with
`jaxunilat.enable_compilation_cache`), looked up here when a command starts."""

from .._internal._compilation_cache import (
    CACHE_DIR_ENV as CACHE_DIR_ENV,
    NO_CACHE_ENV as NO_CACHE_ENV,
    cache_dir as cache_dir,
    enable_compilation_cache as enable_compilation_cache,
)
