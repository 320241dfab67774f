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
