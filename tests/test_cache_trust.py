"""The command line's caches run no one else's code, and a cache directory that cannot
be used costs one line of stderr at most.

Entries of the executable cache are pickles: one planted in the directory must never be
unpickled (each entry carries an HMAC under a per-user key, checked first), and a
directory or key file that someone else can write is refused. These tests run as root
here, and root ignores permission bits: the checks are computed from `st_mode` and
`st_uid` (tested directly, with `os.getuid` patched for ownership), and an unwritable
directory is simulated by a process whose writes there fail."""

import os
import pickle
import stat
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._internal import _executables
from jaxunilat._internal._executables import (
    ExecutableCache,
    disable_executable_cache,
    enable_executable_cache,
)

POSIX = hasattr(os, "getuid")
COMMAND = ["simulate", "ball", "--solver", "rk4", "--dt", "1e-5", "--t1", "0.05"]


class _Plant:
    """A pickle whose loading creates `marker`: what an attacker would plant."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _simulate():
    ball = ju.Ball.table1(2)
    return ju.simulate(ball, ball.paper_initial_state(), 0.3, solver="event", samples=31, throw=False)


def _entries(path):
    return sorted(f for f in os.listdir(path) if f.endswith(".jaxexe"))


@pytest.fixture
def cache_dir(tmp_path):
    yield str(tmp_path / "executables")
    disable_executable_cache()


@pytest.mark.parametrize("layout", ["bare pickle", "forged header"])
def test_a_planted_entry_is_never_unpickled(cache_dir, tmp_path, layout):
    """A pickle planted under an entry's name (bare, or behind a header with a MAC made
    without the key) is removed unread; the program is compiled and kept anew."""
    reference = _simulate()
    enable_executable_cache(cache_dir)
    _simulate()
    (name,) = _entries(cache_dir)
    marker = tmp_path / "planted-code-ran"
    planted = pickle.dumps(_Plant(str(marker)))
    if layout == "forged header":
        planted = _executables.MAGIC + os.urandom(32) + planted
    with open(os.path.join(cache_dir, name), "wb") as f:
        f.write(planted)
    enable_executable_cache(cache_dir)  # a new process: nothing loaded yet
    again = _simulate()
    assert not marker.exists(), "the planted pickle was loaded"
    assert _entries(cache_dir) == [name]
    with open(os.path.join(cache_dir, name), "rb") as f:
        assert f.read(len(_executables.MAGIC)) == _executables.MAGIC
    for a, b in zip(jax.tree_util.tree_leaves(again), jax.tree_util.tree_leaves(reference), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_an_entry_copied_under_another_name_is_refused(cache_dir):
    """The MAC covers the entry's name: a valid entry of one program, copied under the
    name of another's, is not loaded."""
    enable_executable_cache(cache_dir)
    _simulate()
    (name,) = _entries(cache_dir)
    other = "0" * 64
    with (
        open(os.path.join(cache_dir, name), "rb") as src,
        open(os.path.join(cache_dir, other + ".jaxexe"), "wb") as dst,
    ):
        dst.write(src.read())
    cache = ExecutableCache(cache_dir)
    assert cache.prepare() is None
    assert cache._read(other) is None and not os.path.exists(os.path.join(cache_dir, other + ".jaxexe"))
    assert cache._read(name.removesuffix(".jaxexe")) is not None


@pytest.mark.skipif(not POSIX, reason="Unix permissions")
@pytest.mark.parametrize(
    ("mode", "refused"),
    [
        (0o700, False),
        (0o755, False),
        (0o500, False),
        (0o770, True),
        (0o722, True),
        (0o777, True),
        (0o1777, True),
    ],
)
def test_a_directory_others_can_write_is_refused(tmp_path, mode, refused):
    """Any group or other write bit is refused, the sticky bit's too (computed from
    st_mode, so it holds for root as well)."""
    folder = tmp_path / "cache"
    folder.mkdir()
    os.chmod(folder, mode)
    problem = _executables.directory_problem(str(folder))
    assert (problem is not None) == refused
    if refused:
        assert "others can write" in problem and f"{mode:04o}" in problem
    assert (ExecutableCache(str(folder)).prepare() is not None) == refused
    os.chmod(folder, 0o700)


@pytest.mark.skipif(not POSIX, reason="Unix ownership")
def test_a_directory_or_key_another_user_owns_is_refused(tmp_path, monkeypatch):
    cache = ExecutableCache(str(tmp_path / "executables"))
    assert cache.prepare() is None
    owner = os.stat(tmp_path).st_uid
    monkeypatch.setattr(os, "getuid", lambda: owner + 1)
    assert "belongs to user id" in _executables.directory_problem(str(tmp_path))
    with pytest.raises(PermissionError, match="belongs to user id"):
        _executables.secret_key(cache.path)
    assert ExecutableCache(cache.path).prepare() is not None


@pytest.mark.skipif(not POSIX, reason="Unix permissions")
def test_the_key_is_made_0600_once_and_refused_when_others_can_read_it(tmp_path):
    folder = tmp_path / "executables"
    cache = ExecutableCache(str(folder))
    assert cache.prepare() is None
    assert stat.S_IMODE(os.stat(folder).st_mode) == 0o700
    path = folder / _executables.KEY_FILE
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    key = _executables.secret_key(str(folder))
    assert key == cache._key and len(key) == 32
    assert _executables.secret_key(str(folder)) == key  # read back, not made again
    assert [f for f in os.listdir(folder) if f != _executables.KEY_FILE] == []  # no temporary or probe left
    for mode in (0o644, 0o640, 0o604, 0o620):
        os.chmod(path, mode)
        with pytest.raises(PermissionError, match="mode"):
            _executables.secret_key(str(folder))
    os.chmod(path, 0o600)
    path.write_bytes(b"short")
    with pytest.raises(PermissionError, match="bytes"):
        _executables.secret_key(str(folder))
    os.remove(path)
    os.symlink(tmp_path / "elsewhere", path)
    with pytest.raises(PermissionError):
        _executables.secret_key(str(folder))


def _run(argv, env, wrapper=None):
    environ = {k: v for k, v in os.environ.items() if k not in ("JAXUNILAT_NO_CACHE", "JAXUNILAT_CACHE_DIR")}
    environ.update(env)
    command = [sys.executable, *(wrapper or ["-m", "jaxunilat"]), *argv]
    done = subprocess.run(command, capture_output=True, text=True, env=environ, timeout=300)
    assert done.returncode == 0, done.stderr
    return done


def _files(path):
    return sorted(name for _, _, files in os.walk(path) for name in files)


@pytest.mark.skipif(not POSIX, reason="Unix permissions")
def test_the_command_line_refuses_a_shared_directory_in_one_line(tmp_path):
    cache = tmp_path / "shared"
    cache.mkdir()
    os.chmod(cache, 0o777)
    done = _run(COMMAND, {"JAXUNILAT_CACHE_DIR": str(cache)})
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"jaxunilat: warning: not using the cache directory {cache}: others can write")
    assert "chmod 700" in lines[0] and "JAXUNILAT_CACHE_DIR" in lines[0] and "--no-cache" in lines[0]
    assert _files(cache) == []
    assert "x(t1)" in done.stdout


def test_the_command_line_makes_its_directories_private(tmp_path):
    cache = tmp_path / "new" / "jaxunilat"
    done = _run(COMMAND, {"JAXUNILAT_CACHE_DIR": str(cache)})
    assert done.stderr == ""
    if POSIX:
        assert stat.S_IMODE(os.stat(cache).st_mode) == 0o700
        assert stat.S_IMODE(os.stat(cache / "executables").st_mode) == 0o700
        assert stat.S_IMODE(os.stat(cache / "executables" / _executables.KEY_FILE).st_mode) == 0o600


#: Runs the command line in a process whose writes under the directory argv[1] fail as
#: they would for a user without write permission there (root's would not).
READ_ONLY = """
import builtins, errno, io, os, sys
ROOT = os.path.abspath(sys.argv[1])
def under(path):
    try:
        path = os.path.abspath(os.fsdecode(path))
    except TypeError:
        return False
    return path == ROOT or path.startswith(ROOT + os.sep)
def deny(path):
    raise PermissionError(errno.EACCES, "Permission denied", os.fsdecode(path))
real_open, real_os_open, real_mkdir = builtins.open, os.open, os.mkdir
def fake_open(file, mode="r", *args, **kwargs):
    if isinstance(file, (str, bytes, os.PathLike)) and under(file) and any(c in mode for c in "wax+"):
        deny(file)
    return real_open(file, mode, *args, **kwargs)
def fake_os_open(path, flags, *args, **kwargs):
    if under(path) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
        deny(path)
    return real_os_open(path, flags, *args, **kwargs)
def fake_mkdir(path, *args, **kwargs):
    if under(path) and not os.path.isdir(path):
        deny(path)
    return real_mkdir(path, *args, **kwargs)
builtins.open = io.open = fake_open
os.open, os.mkdir = fake_os_open, fake_mkdir
from jaxunilat._cli._main import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("solver", ["rk4", "event"])
def test_a_read_only_directory_costs_one_line_at_most(tmp_path, solver):
    """Before: every program JAX failed to write warned (a few lines each, per program)."""
    cache = tmp_path / "read-only"
    cache.mkdir(mode=0o700)
    argv = [
        "simulate",
        "ball",
        "--solver",
        solver,
        "--t1",
        "0.05",
        *(["--dt", "1e-5"] if solver == "rk4" else []),
    ]
    done = _run([str(cache), *argv], {"JAXUNILAT_CACHE_DIR": str(cache)}, wrapper=["-c", READ_ONLY])
    lines = done.stderr.splitlines()
    assert len(lines) <= 1, done.stderr
    assert all("cannot write to it" in line and str(cache) in line for line in lines)
    assert "x(t1)" in done.stdout and _files(cache) == []


def test_a_directory_under_a_file_costs_one_line_at_most(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    done = _run(COMMAND, {"JAXUNILAT_CACHE_DIR": str(blocker / "cache")})
    assert len(done.stderr.splitlines()) <= 1, done.stderr
    assert "x(t1)" in done.stdout


def test_the_directory_checks_are_cheap(tmp_path):
    """Measured, not asserted tightly: a few stats, a probe file and the key's read."""
    import time

    folder = str(tmp_path / "executables")
    ExecutableCache(folder).prepare()
    start = time.perf_counter()
    for _ in range(100):
        assert ExecutableCache(folder).prepare() is None
    assert (time.perf_counter() - start) / 100 < 0.01


def test_refusals_turn_the_cache_off_quietly(tmp_path, monkeypatch):
    """A cache whose directory is refused makes plain calls (no entry, no error)."""
    folder = tmp_path / "executables"
    folder.mkdir()
    os.chmod(folder, 0o777)
    reference = _simulate()
    cache = ExecutableCache(str(folder))
    try:
        _executables._ACTIVE[:] = [cache]
        again = _simulate()
    finally:
        disable_executable_cache()
        os.chmod(folder, 0o700)
    assert cache.prepare() is not None and _entries(folder) == []
    assert float(again.y1[0]) == float(reference.y1[0])
