"""Checks of the environment variables that decide how JAX starts, before any work.

Two variables can stop a run before it begins, in ways the command line cannot catch
once JAX has started its backend:

- `JAX_PLATFORMS` naming a backend that is not installed (e.g. `cuda` on a CPU-only
  install): JAX raises a bare `AssertionError` at the first computation.
- `XLA_FLAGS` holding a flag XLA does not know: XLA aborts the whole process with a
  fatal log line when it starts its backend, which no `try` can catch.

`check_environment` turns each into one `UsageError` line naming the variable and its
value (exit 2). The `XLA_FLAGS` check starts XLA's CPU client in a short subprocess
(about 0.3-0.7 s: an `import jaxlib` and a client start), and only when the user set
the variable and JAX has not started its backend yet; with the variable unset, or
holding nothing but the loop-kernel option that `import jaxunilat` adds (XLA knows it),
it does nothing.
"""

from __future__ import annotations

import os
import subprocess
import sys

from .._internal._errors import UsageError

#: The child: start XLA's CPU client, which parses XLA_FLAGS (and aborts on a bad one).
_PROBE = """
try:
    from jaxlib import xla_client
    xla_client.make_cpu_client()
except AttributeError:  # a jaxlib without make_cpu_client
    import jax
    jax.devices("cpu")
"""
#: Seconds the child may take before the check gives up (and lets the run go on).
PROBE_TIMEOUT_S = 60.0


def _backend_started() -> bool:
    from .._internal._loop_kernels import _backend_started as started

    return started()


def check_xla_flags(user_flags: str | None) -> None:
    """Raise `UsageError` when XLA would abort on `XLA_FLAGS` at backend start.

    `user_flags` is the variable as the user set it (None or empty: nothing is checked,
    at no cost). The check runs the current environment's `XLA_FLAGS` (the user's plus
    what the command line adds) in a subprocess; it is skipped once JAX has started its
    backend (XLA then read the variable already, without aborting), and for the
    loop-kernel option alone (`jaxunilat._internal._loop_kernels`).
    """
    from .._internal._loop_kernels import without_option

    # The option `import jaxunilat` adds (here, or in a parent process) is XLA's own.
    if not without_option(user_flags or "") or _backend_started():
        return
    try:
        child = subprocess.run(
            [sys.executable, "-c", _PROBE],
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            env=dict(os.environ, JAX_PLATFORMS="cpu", TF_CPP_MIN_LOG_LEVEL="0"),
        )
    except (OSError, subprocess.TimeoutExpired):  # cannot tell: let the run report what it can
        return
    if child.returncode == 0:
        return
    lines = [line for line in child.stderr.splitlines() if "XLA_FLAGS" in line or "flag" in line.lower()]
    if child.returncode > 0 and not lines:
        return  # a Python error in the child, not XLA's abort: not about XLA_FLAGS
    reason = lines[-1].split("] ", 1)[-1].strip() if lines else f"XLA aborts (signal {-child.returncode})"
    raise UsageError(
        f"XLA_FLAGS={user_flags!r}: XLA cannot start with it ({reason}); fix or unset XLA_FLAGS "
        "(XLA's flags: https://openxla.org/xla/flags_guidance)"
    )


def check_jax_platforms() -> None:
    """Raise `UsageError` when `JAX_PLATFORMS` is set and JAX cannot start its backend.

    Starts the backend (which the run does anyway), only when the variable is set.
    """
    value = os.environ.get("JAX_PLATFORMS")
    if not value:
        return
    import jax

    try:
        jax.devices()
    except Exception as err:  # AssertionError (a missing plugin), RuntimeError (an unknown name)
        reason = " ".join(str(err).split()) or (
            "that backend is not installed (e.g. jax[cuda12] for cuda) or has no device"
        )
        raise UsageError(
            f"JAX_PLATFORMS={value!r}: JAX cannot start that backend ({reason}); unset JAX_PLATFORMS "
            "or set JAX_PLATFORMS=cpu"
        ) from None


def check_environment(user_xla_flags: str | None) -> None:
    """Both checks, `XLA_FLAGS` first (starting a backend with bad flags would abort)."""
    check_xla_flags(user_xla_flags)
    check_jax_platforms()
