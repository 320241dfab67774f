"""The command line's persistent compilation cache: on by default in the user cache
directory, moved by JAXUNILAT_CACHE_DIR, off with --no-cache or JAXUNILAT_NO_CACHE=1.

Each case runs the console entry point in a fresh process (the suite itself runs with
JAXUNILAT_NO_CACHE=1, set in conftest.py, and never touches a cache)."""

import os
import subprocess
import sys

import pytest

COMMAND = ["simulate", "ball", "--solver", "rk4", "--dt", "1e-5", "--t1", "0.05"]


def _run(tmp_path, *global_flags, **env):
    environ = {k: v for k, v in os.environ.items() if k not in ("JAXUNILAT_NO_CACHE", "JAXUNILAT_CACHE_DIR")}
    environ.update({"XDG_CACHE_HOME": str(tmp_path / "xdg"), **env})
    argv = [sys.executable, "-m", "jaxunilat", *global_flags, *COMMAND]
    out = subprocess.run(argv, capture_output=True, text=True, env=environ, timeout=300)
    assert out.returncode == 0, out.stderr


def _entries(path):
    return sorted(name for _, _, files in os.walk(path) for name in files)


def test_default_location_then_reuse(tmp_path):
    cache = tmp_path / "xdg" / "jaxunilat"
    _run(tmp_path)
    first = _entries(cache)
    assert first, "nothing was cached in $XDG_CACHE_HOME/jaxunilat"
    _run(tmp_path)  # a second run reads the cache and compiles nothing new
    assert _entries(cache) == first


@pytest.mark.parametrize(("flags", "env"), [((), {"JAXUNILAT_NO_CACHE": "1"}), (("--no-cache",), {})])
def test_opt_out(tmp_path, flags, env):
    _run(tmp_path, *flags, **env)
    assert _entries(tmp_path / "xdg" / "jaxunilat") == []


def test_jaxunilat_cache_dir_moves_it(tmp_path):
    _run(tmp_path, JAXUNILAT_CACHE_DIR=str(tmp_path / "elsewhere"))
    assert _entries(tmp_path / "elsewhere") and _entries(tmp_path / "xdg" / "jaxunilat") == []


SCRIPT = """
import sys, jaxunilat as ju
print(ju.enable_compilation_cache(sys.argv[1]))
ju.simulate(ju.Ball.table1(2), (-0.4, -1 / 0.122), 0.05, solver="event", samples=11)
"""


def test_the_python_api_uses_the_cache_when_asked(tmp_path):
    """`jaxunilat.enable_compilation_cache(path)` in a script: the compiled programs land in
    `path`, and a second run of the script compiles nothing new; without the call, a
    script leaves JAX's settings alone (nothing cached)."""
    environ = {k: v for k, v in os.environ.items() if k not in ("JAXUNILAT_NO_CACHE", "JAXUNILAT_CACHE_DIR")}
    environ["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    cache = tmp_path / "cache"
    for _ in range(2):
        out = subprocess.run(
            [sys.executable, "-c", SCRIPT, str(cache)],
            capture_output=True,
            text=True,
            env=environ,
            timeout=300,
        )
        assert out.returncode == 0 and out.stdout.strip() == str(cache), out.stderr
        if _ == 0:
            first = _entries(cache)
    assert first and _entries(cache) == first
    plain = SCRIPT.replace("print(ju.enable_compilation_cache(sys.argv[1]))", "print(sys.argv[1])")
    out = subprocess.run(
        [sys.executable, "-c", plain, str(tmp_path / "unused")],
        capture_output=True,
        text=True,
        env=environ,
        timeout=300,
    )
    assert out.returncode == 0 and not (tmp_path / "xdg").exists() and not (tmp_path / "unused").exists()
