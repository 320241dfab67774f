"""Compiled programs kept on disk: the command line's second run skips tracing, lowering
and compiling.

JAX's persistent compilation cache (`jax_compilation_cache_dir`) saves the compile, but
finds its key by tracing and lowering the program first: for the event mode that is
about 1 s on 2 cores, more than a short solve, and half of a warm `jaxunilat simulate`.
This cache keys a call *before* tracing, on everything that decides its program, and
keeps the compiled executable (`jax.experimental.serialize_executable`) with a
zero-size template of the output's structure. A hit loads it (~0.2 s) and calls it.

A kept program is always compiled afresh, never read back from JAX's persistent
compilation cache: on the CPU (jaxlib 0.10) an executable that JAX deserialized from its
cache serializes again without the code of some of its fusions, and the copy fails
when called ("Function ... not found"). `_compile_fresh` gives the compile a key of its
own in JAX's cache (a compile option at its default value) and writes nothing there.
A kept entry that loads but fails on its first call is deleted and compiled afresh.

The key is a SHA-256 digest of:

- the format below, the versions of jax and jaxlib, and a digest of the source files
  of jaxunilat and of the package that defines the function (`identify`'s, say): a new
  release or an edited checkout never runs a stale program;
- the backend (platform, device kind, platform version), the host CPU (its model and
  instruction-set flags: a cache directory shared between machines never runs code
  built for another CPU), `XLA_FLAGS`, and JAX's settings other than its caches';
- the function's name, its static arguments, the arguments' tree structure (which
  holds the models' and settings' static fields) and each leaf's shape, dtype and weak
  type.

Trust: an entry is a pickle, and unpickling runs code, so the cache only reads a
directory that is yours alone and only unpickles what it wrote itself. The directory
(and the command line's, above it) must be owned by the current user and have no group
or other write bit, as ssh requires of `~/.ssh` (`directory_problem`); the cache creates
them 0700. Each entry carries an HMAC-SHA256 of its bytes and name under a per-user
secret key (`KEY_FILE`: 32 random bytes, created 0600 beside the entries with
`O_CREAT | O_EXCL`, refused when another user owns it or its mode lets anyone else read
or write it). The HMAC is checked before anything is unpickled: an entry that fails is
never unpickled; it is removed and the program compiled afresh. Not protected against:
whoever can read the key and write the directory (your own user, or root). A directory
or key that fails these checks turns the cache off for the process (`prepare` says
why; the command line prints it once).

A call whose key cannot be written faithfully (a repr with an address in it) is not
cached. Any failure to read, load or write an entry falls back to the plain compiled
call, and an unreadable entry is deleted. Only programs with no host callbacks can be
serialized: `simulate` uses the cache for `throw=False` only (and traces diffrax's own
input checks away, having made them itself), and a program that has some anyway is
called plainly, so that JAX's persistent cache keeps its compile. At most `max_entries`
files are kept (the least recently used go first); deleting the directory is always
safe.

Callers: `simulate`'s top-level call, and `identify`'s compiled residuals
(`kept_call`, for a `jax.jit` function whose arguments' leaves are all arrays). Only the
command line turns the cache on (`enable_executable_cache`, beside the compilation
cache, in `<cache dir>/executables`); the Python API and the test suite leave it off.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import os
import pickle
import secrets
import stat
import sys
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from ._io import special_kind, write_atomically

#: Bumped when the file layout or the key's recipe changes.
FORMAT = 4
#: Where, within the command line's cache directory, the executables go.
SUBDIR = "executables"
#: The default number of entries kept on disk (each ~1–2 MB for the event mode).
MAX_ENTRIES = 64
#: A compile option at its default value (it only embeds the HLO in the executable, for
#: debugging): it changes the key of a kept program's compile in JAX's persistent cache.
_OWN_KEY_OPTION = {"xla_embed_ir_in_executable": False}
_MIN_COMPILE_TIME = "jax_persistent_cache_min_compile_time_secs"
#: The secret key of the entries' HMACs, beside them (see the module docstring).
KEY_FILE = ".key"
#: Its size in bytes.
KEY_BYTES = 32
#: What an entry starts with: the layout, then the HMAC-SHA256 of the rest, then the pickle.
MAGIC = b"JUXEXE%02d" % FORMAT
#: Entries larger than this are not read (the event mode's are ~1.6 MB).
MAX_ENTRY_BYTES = 1 << 30
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)

_SOURCE_DIGEST: dict[str, str] = {}


def _source_digest(package: str = "jaxunilat") -> str:
    """A digest of every .py file of an imported package (once per process and package)."""
    if package not in _SOURCE_DIGEST:
        module = sys.modules.get(package)
        root = os.path.dirname(os.path.abspath(getattr(module, "__file__", None) or __file__))
        digest = hashlib.sha256()
        for folder, dirs, files in os.walk(root):
            dirs.sort()
            for name in sorted(f for f in files if f.endswith(".py")):
                path = os.path.join(folder, name)
                digest.update(os.path.relpath(path, root).encode())
                with open(path, "rb") as f:
                    digest.update(f.read())
        _SOURCE_DIGEST[package] = digest.hexdigest()
    return _SOURCE_DIGEST[package]


@functools.cache
def _host_cpu() -> str:
    """The host CPU's model and feature flags (Linux: /proc/cpuinfo), else its architecture."""
    import platform

    found: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("model name", "flags", "Features", "CPU implementer", "CPU part"):
                    found.setdefault(key, value.strip())
    except OSError:
        pass
    return repr((platform.machine(), platform.processor(), sorted(found.items())))


#: `_environment()`'s text by (XLA_FLAGS, JAX's settings): written once per process and
#: setting, not on every call (its repr is most of a key's cost).
_ENVIRONMENTS: dict[tuple, str] = {}


def _environment() -> str:
    """What besides the call decides a compiled program (see the module docstring)."""
    fingerprint = (os.environ.get("XLA_FLAGS", ""), tuple(jax.config.values.items()))
    try:
        return _ENVIRONMENTS[fingerprint]
    except KeyError:
        text = _ENVIRONMENTS[fingerprint] = _environment_text(fingerprint[0])
    except TypeError:  # a setting that cannot be hashed: written afresh
        text = _environment_text(fingerprint[0])
    return text


def _environment_text(xla_flags: str) -> str:
    import jaxlib

    # The device new computations go to: JAX's default one, or the one placed by
    # `jax.default_device` (the host, for latency-bound work on an accelerator machine).
    device = jax.config.jax_default_device or jax.devices()[0]
    if isinstance(device, str):  # a platform name
        device = jax.devices(device)[0]
    settings = sorted((k, v) for k, v in jax.config.values.items() if "cache" not in k)
    return repr(
        (
            FORMAT,
            jax.__version__,
            jaxlib.__version__,
            device.platform,
            device.device_kind,
            device.client.platform_version,
            xla_flags,
            settings,
        )
    )


def call_key(name: str, args: tuple, static: tuple, package: str = "jaxunilat") -> str | None:
    """The cache key of `name(*args, *static)` (`static`: its static arguments; `package`:
    the one that defines the function, whose source counts too), or None where it cannot
    be written faithfully (a leaf that is not an array, or an address in a repr)."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    avals = []
    for leaf in leaves:
        if not isinstance(leaf, (jax.Array, np.ndarray)) or isinstance(leaf, jax.core.Tracer):
            return None
        avals.append((leaf.shape, str(leaf.dtype), bool(getattr(leaf, "weak_type", False))))
    sources = (_source_digest("jaxunilat"), package, _source_digest(package))
    text = repr((name, static, str(tree), avals, sources, _host_cpu()))
    if " at 0x" in text:
        return None
    return hashlib.sha256((_environment() + text).encode()).hexdigest()


def directory_problem(path: str) -> str | None:
    """Why `path` may not hold cached programs, or None when it may: it must be a
    directory that the current user owns (where the platform has user ids) and that no
    one else can write to (no group or other write bit, whatever the sticky bit). The
    answer comes from `os.stat` alone, not from a write that the kernel refuses (root
    ignores permission bits)."""
    try:
        st = os.stat(path)
    except OSError as err:
        return f"cannot read it ({err.strerror or err})"
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a directory"
    getuid = getattr(os, "getuid", None)
    if getuid is not None and st.st_uid != getuid():
        return f"it belongs to user id {st.st_uid}, not to you (user id {getuid()})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"others can write to it (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def private_directory(path: str) -> str | None:
    """Make `path` (mode 0700 where it is new) and check it (`directory_problem`) and that
    this process can write there (a file created and removed: a read-only directory or
    file system turns the cache off at once rather than failing on every write). Returns
    why it cannot be used, or None."""
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
    except OSError as err:
        return f"cannot create it ({err.strerror or err})"
    problem = directory_problem(path)
    if problem is not None:
        return problem
    probe = os.path.join(path, f".probe.{os.getpid()}.{secrets.token_hex(4)}")
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o600))
        os.remove(probe)
    except OSError as err:
        return f"cannot write to it ({err.strerror or err})"
    return None


def _key_problem(fd: int) -> str | None:
    st = os.fstat(fd)
    getuid = getattr(os, "getuid", None)
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    if getuid is not None and st.st_uid != getuid():
        return f"belongs to user id {st.st_uid}, not to you"
    if getuid is not None and st.st_mode & 0o077:
        return f"can be read or written by others (mode {stat.S_IMODE(st.st_mode):04o}; it must be 0600)"
    return None


def secret_key(folder: str) -> bytes:
    """The per-user HMAC key in `folder`'s `KEY_FILE`, created where there is none
    (32 random bytes, mode 0600, `O_CREAT | O_EXCL`: written whole under a temporary name
    and linked into place, so that a concurrent process never reads half of it).

    **Raises:** `PermissionError` naming the problem for a key file that another user
    owns, that others can read or write, or that is not a regular file of 32 bytes;
    `OSError` when it cannot be made."""
    path = os.path.join(folder, KEY_FILE)
    for _ in range(2):
        try:
            fd = os.open(path, os.O_RDONLY | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
        except FileNotFoundError:
            _create_key(path)
            continue
        except OSError as err:
            raise PermissionError(f"its key file {path} cannot be opened ({err.strerror or err})") from None
        try:
            problem = _key_problem(fd)
            key = b"" if problem else os.read(fd, KEY_BYTES + 1)
        finally:
            os.close(fd)
        if problem is None and len(key) != KEY_BYTES:
            problem = f"holds {len(key)} bytes, not {KEY_BYTES}"
        if problem is not None:
            raise PermissionError(f"its key file {path} {problem}")
        return key
    raise OSError(f"its key file {path} could not be created")


def _create_key(path: str) -> None:
    tmp = f"{path}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o600)
    try:
        try:
            os.write(fd, secrets.token_bytes(KEY_BYTES))
            os.fsync(fd)
        finally:
            os.close(fd)
        try:
            os.link(tmp, path)  # fails where another process made it first: theirs is used
        except FileExistsError:
            pass
        except OSError:  # a file system without hard links: a rename, where there is none yet
            if not os.path.lexists(path):
                os.rename(tmp, path)
    finally:
        _remove(tmp)


def _mac(key: bytes, name: str, body: bytes | memoryview) -> bytes:
    """The HMAC-SHA256 of an entry: its layout, its name (an entry copied under another
    key's name fails) and its pickle."""
    mac = hmac.new(key, MAGIC, hashlib.sha256)
    mac.update(name.encode())
    mac.update(body)
    return mac.digest()


class ExecutableCache:
    """Compiled programs on disk, by `call_key` (see the module docstring)."""

    def __init__(self, path: str, max_entries: int = MAX_ENTRIES):
        self.path = path
        self.max_entries = max_entries
        self._loaded: dict[str, Any] = {}
        self._key: bytes | None = None
        self._problem: str | None = None

    def _file(self, key: str) -> str:
        return os.path.join(self.path, key + ".jaxexe")

    def prepare(self) -> str | None:
        """Make and check the directory (`private_directory`) and read or create the
        secret key (`secret_key`), once. Returns why the cache cannot be used (it then
        only makes plain calls), or None."""
        if self._key is None and self._problem is None:
            self._problem = private_directory(self.path)
            if self._problem is None:
                try:
                    self._key = secret_key(self.path)
                except OSError as err:
                    self._problem = str(err)
        return self._problem

    def call(self, name: str, jitted: Callable, args: tuple, static: tuple):
        """`jitted(*args, *static)`, from a kept executable where there is one (`static`:
        the trailing static arguments)."""
        key = call_key(name, args, static, _package_of(jitted))
        if key is None or self.prepare() is not None:
            return jitted(*args, *static)
        compiled = self._loaded.get(key)
        if compiled is not None:
            return compiled(*args)
        compiled = self._load(key, args)
        if compiled is not None:
            try:
                return compiled(*args)
            except Exception:  # an entry that loads but cannot run: compile afresh
                del self._loaded[key]
                _remove(self._file(key))
        compiled = _compile_fresh(jitted, args, static)
        if compiled is None:  # host callbacks, or an XLA without the option: plain calls
            self._loaded[key] = functools.partial(_plain_call, jitted, static)
            return jitted(*args, *static)
        out = compiled(*args)
        self._loaded[key] = compiled
        self._store(key, compiled, out)
        return out

    def _read(self, key: str) -> bytes | None:
        """The pickle of entry `key` when its HMAC holds; None where there is no entry.
        Anything else at its name (a FIFO, a symlink, a damaged or foreign file) is
        removed unread and gives None."""
        path = self._file(key)
        if special_kind(path) is not None:
            return None  # a device or FIFO planted at an entry's name is never opened (no hang)
        try:
            fd = os.open(path, os.O_RDONLY | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0))
        except FileNotFoundError:
            return None
        except OSError:  # a symlink (ELOOP) or unreadable: never followed
            _remove(path)
            return None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_ENTRY_BYTES:
                data = b""
            else:
                with os.fdopen(os.dup(fd), "rb") as f:
                    data = f.read()
        except OSError:
            data = b""
        finally:
            os.close(fd)
        head = len(MAGIC) + hashlib.sha256().digest_size
        body = memoryview(data)[head:]
        if (
            len(data) <= head
            or data[: len(MAGIC)] != MAGIC
            or not hmac.compare_digest(data[len(MAGIC) : head], _mac(self._key, key, body))
        ):
            if special_kind(path) is None:  # a device or FIFO is left alone, never opened again
                _remove(path)
            return None
        return bytes(body)

    def _load(self, key: str, args: tuple):
        from jax.experimental import serialize_executable

        body = self._read(key)  # the HMAC is checked before anything is unpickled
        if body is None:
            return None
        path = self._file(key)
        try:
            payload, template = pickle.loads(body)
            in_tree = jax.tree_util.tree_structure((args, {}))
            out_tree = jax.tree_util.tree_structure(template)
            compiled = serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
        except Exception:  # an incompatible entry of ours: compile afresh
            _remove(path)
            return None
        try:
            os.utime(path)  # least recently used goes first
        except OSError:  # removed meanwhile by another process's eviction
            pass
        self._loaded[key] = compiled
        return compiled

    def _store(self, key: str, compiled, out) -> None:
        from jax.experimental import serialize_executable

        try:
            payload, _, _ = serialize_executable.serialize(compiled)
            template = jax.tree_util.tree_map(lambda x: np.zeros(0, x.dtype), out)
            body = pickle.dumps((payload, template), protocol=pickle.HIGHEST_PROTOCOL)
            os.makedirs(self.path, mode=0o700, exist_ok=True)
            with write_atomically(self._file(key), "wb", special="refuse") as f:
                f.write(MAGIC + _mac(self._key, key, body))
                f.write(body)
        except Exception:  # a full disk, or a program that cannot be serialized
            return
        self._evict()

    def _evict(self) -> None:
        try:
            names = os.listdir(self.path)
        except OSError:
            return
        entries = [os.path.join(self.path, f) for f in names if f.endswith(".jaxexe")]
        if len(entries) <= self.max_entries:
            return
        entries.sort(key=_mtime)
        for path in entries[: len(entries) - self.max_entries]:
            _remove(path)


def _compile_fresh(jitted: Callable, args: tuple, static: tuple):
    """`jitted` compiled for `(*args, *static)` by XLA itself, not read back from JAX's
    persistent compilation cache (whose copies do not serialize whole: see the module
    docstring). The compile has a key of its own there, and nothing is written under it
    (the minimum compile time for a write is set to infinity meanwhile). None where XLA
    refuses the option (a release without it), and where the program has host callbacks
    (they do not serialize): the caller
    then calls `jitted` plainly, so that JAX's persistent cache keeps the compile (the
    call reuses this lowering), and keeps nothing itself."""
    lowered = jitted.lower(*args, *static)
    if _has_host_callbacks(lowered):
        return None
    previous = jax.config.values[_MIN_COMPILE_TIME]
    jax.config.update(_MIN_COMPILE_TIME, float("inf"))
    try:
        return lowered.compile(compiler_options=_OWN_KEY_OPTION)
    except jax.errors.JaxRuntimeError:  # "No such compile option"
        return None
    finally:
        jax.config.update(_MIN_COMPILE_TIME, previous)


def _has_host_callbacks(lowered) -> bool:
    """Whether a lowered program calls back into Python (`jax.pure_callback`,
    `equinox.error_if`, ...): JAX lists them among its compile arguments (a private
    attribute: where it is missing, the serialization's own failure decides)."""
    compile_args = getattr(getattr(lowered, "_lowering", None), "compile_args", None)
    return bool(isinstance(compile_args, dict) and compile_args.get("host_callbacks"))


def _plain_call(jitted: Callable, static: tuple, *args):
    return jitted(*args, *static)


def _package_of(fn) -> str:
    """The top-level package that defines `fn` (a `jax.jit` function keeps its module)."""
    return (getattr(fn, "__module__", None) or "jaxunilat").split(".")[0]


def _mtime(path: str) -> float:
    try:
        return os.path.getmtime(path)
    except OSError:
        return 0.0


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


_ACTIVE: list[ExecutableCache] = []


def enable_executable_cache(path: str, max_entries: int = MAX_ENTRIES) -> ExecutableCache:
    """Keep the compiled programs of `kept_call` (`simulate`, `identify`'s residuals) in
    `path` for the rest of the process (the command line does this; see the module
    docstring)."""
    _ACTIVE[:] = [ExecutableCache(path, max_entries)]
    return _ACTIVE[0]


def set_executable_cache(cache: ExecutableCache) -> ExecutableCache:
    """Use `cache` (made and checked by the caller: `ExecutableCache.prepare`) for the rest
    of the process."""
    _ACTIVE[:] = [cache]
    return cache


def disable_executable_cache() -> None:
    """Stop using the executable cache in this process."""
    _ACTIVE.clear()


def executable_cache() -> ExecutableCache | None:
    """The process's executable cache, or None when it is off (the default)."""
    return _ACTIVE[0] if _ACTIVE else None


def kept_call(name: str, jitted: Callable, args: tuple, static: tuple = ()):
    """`jitted(*args, *static)`, through the executable cache when it is on.

    `jitted` is a `jax.jit` function whose trailing `static` arguments are static and
    whose other arguments' leaves are arrays; `name` says what it is in the key (e.g.
    `"identify.evaluate_rows"`). Its program must have no host callbacks.
    """
    cache = executable_cache()
    return jitted(*args, *static) if cache is None else cache.call(name, jitted, args, static)
