"""Loop kernels: let XLA:CPU compile each small loop into one kernel (on by default).

XLA:CPU runs a compiled program as a sequence of "thunks" (one per fused kernel,
copy or control-flow op), and each costs about 60–100 ns to launch whatever its
arithmetic. The event mode's loop body is about 100 thunks per step, so a step costs
5–8 µs although its arithmetic (a Runge–Kutta step on a 2-vector) takes well under
one. XLA:CPU has a pass that instead compiles a whole `while` loop, control flow
included, into one function when the loop touches fewer bytes per iteration than a
threshold (`xla_cpu_small_while_loop_byte_threshold`, 1 KiB by default, far below the
event loop's few tens of KiB). Raising the threshold makes the event mode's steps
about 10× cheaper and its compilation about a quarter faster (README, Performance).

The threshold is one of XLA's backend options, which JAX cannot set per function:
XLA reads them once per process from the `XLA_FLAGS` environment variable when JAX
starts its CPU backend (at the first computation). So `import jaxunilat` adds the
option to `XLA_FLAGS` itself (`apply_on_import`), as it enables float64, when JAX has
not started its backend yet; child processes inherit the variable. It changes nothing
else, and results differ from XLA's default only at rounding level.

- Opt out: set the environment variable `JAXUNILAT_NO_LOOP_KERNELS=1` before the import
  (`XLA_FLAGS` is then left as it is).
- Too late: when JAX started its CPU backend before the import (a program that imports
  jax and computes first), the option cannot take effect; the first `simulate` warns
  once (`warn_if_missing`) with the fix: import jaxunilat before the first JAX
  computation, or start Python with
  `XLA_FLAGS=--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1048576`.
- Explicit control: `use_loop_kernels(byte_threshold)` before the first computation
  (with the opt-out set, or another threshold); an option already in `XLA_FLAGS` is
  always left as it is.
"""

from __future__ import annotations

import os
import re
import sys
import warnings

from ._errors import InputError

OPTION = "xla_cpu_small_while_loop_byte_threshold"
#: Loops that touch up to 1 MiB per iteration become one kernel: the event mode's loop
#: (tens of KiB per step) and each row of a per-row sweep, but not a loop vmapped over
#: thousands of rows, whose kernels amortize their launch cost over the batch anyway.
DEFAULT_BYTES = 1 << 20
_EXTRA = "--xla_backend_extra_options="
#: The environment variable that keeps `import jaxunilat` from adding the option (any
#: value but "", "0", "false", "no").
OPT_OUT = "JAXUNILAT_NO_LOOP_KERNELS"
#: (XLA_FLAGS before, after) where this process added the option itself, else None.
_ADDED: list[tuple[str | None, str]] = []
#: Whether the first `simulate` already looked for the option (`warn_if_missing`).
_CHECKED: list[bool] = []


def opted_out() -> bool:
    """Whether `JAXUNILAT_NO_LOOP_KERNELS` asks for XLA's default CPU options."""
    return os.environ.get(OPT_OUT, "").strip().lower() not in ("", "0", "false", "no")


def apply_on_import() -> bool:
    """Add the option to `XLA_FLAGS` with the default threshold (what `import jaxunilat`
    does): not when opted out (`OPT_OUT`), when an option is there already, or when JAX
    has started its backend. True if it added it."""
    if opted_out():
        return False
    flags = os.environ.get("XLA_FLAGS")
    if loop_kernel_bytes(flags or "") is not None:
        return False
    return _add(flags, DEFAULT_BYTES)


def _add(flags: str | None, byte_threshold: int) -> bool:
    """Add the option to `flags` (the current `XLA_FLAGS`) if the backend has not started."""
    new = _loop_setting(flags or "", byte_threshold)
    if not add_xla_flags(new):
        return False
    _ADDED[:] = [(flags, new)]
    return True


def user_flags(flags: str | None) -> str | None:
    """`flags` (an `XLA_FLAGS` value) without the option this process added itself: what
    the user set (None where that was nothing)."""
    if _ADDED and flags == _ADDED[0][1]:
        return _ADDED[0][0]
    return flags


def without_option(flags: str) -> str:
    """`flags` (an `XLA_FLAGS` value) without the loop-kernel option; a backend-options
    flag left empty goes too."""
    for pattern in (rf"{OPTION}=\d+,", rf",{OPTION}=\d+", rf"{OPTION}=\d+"):
        flags = re.sub(pattern, "", flags)
    return " ".join(word for word in flags.split() if word != _EXTRA)


def _fix() -> str:
    return f"XLA_FLAGS='{_EXTRA}{OPTION}={DEFAULT_BYTES}'"


def warn_if_missing(stacklevel: int = 3) -> None:
    """Once per process (the first `simulate`): warn when JAX's CPU backend runs without
    the option, because it started before `import jaxunilat` could set it. Silent when
    opted out and on other backends (GPU: the option has no effect); where the backend
    has not started yet, the option is added instead."""
    if _CHECKED:
        return
    _CHECKED.append(True)
    if opted_out() or loop_kernel_bytes() is not None:
        return
    if not _backend_started() and _add(os.environ.get("XLA_FLAGS"), DEFAULT_BYTES):
        return
    import jax

    if jax.default_backend() != "cpu":
        return
    warnings.warn(
        "jaxunilat: JAX started its CPU backend before jaxunilat could set XLA's loop-kernel option, so "
        "the event mode's step loops run several times slower (each step launches ~100 separate kernels). "
        "Import jaxunilat before the first JAX computation, or start Python with "
        f"{_fix()}; set {OPT_OUT}=1 to keep XLA's defaults without this warning.",
        RuntimeWarning,
        stacklevel=stacklevel,
    )


def _backend_started() -> bool:
    """Whether JAX has started a backend (after which XLA_FLAGS is no longer read)."""
    if "jax" not in sys.modules:  # not imported: nothing started (and nothing to import here)
        return False
    try:
        from jax._src import xla_bridge
    except ImportError:  # pragma: no cover - a JAX without this module
        return False
    started = getattr(xla_bridge, "backends_are_initialized", None)
    return bool(started()) if started is not None else False


def loop_kernel_bytes(flags: str | None = None) -> int | None:
    """The loop-kernel threshold that `XLA_FLAGS` (or `flags`) sets, bytes; None if unset
    (XLA's default, 1 KiB)."""
    flags = os.environ.get("XLA_FLAGS", "") if flags is None else flags
    match = re.search(rf"(?:^|[\s,=]){OPTION}=(\d+)", flags)
    return int(match.group(1)) if match else None


def use_loop_kernels(byte_threshold: int = DEFAULT_BYTES) -> bool:
    """Let XLA:CPU compile each small `while` loop into one kernel (process-wide).

    `import jaxunilat` already does this with the default threshold (unless the
    environment variable `JAXUNILAT_NO_LOOP_KERNELS=1` is set, or JAX started its
    backend first); call it for explicit control, e.g. another threshold after opting
    out. The event mode's step loop then runs about 10× faster and compiles about a
    quarter faster; results change only at rounding level (about 1e-12 m on Table 1's
    examples). Call it before the first JAX computation of the process (right after the
    imports): it adds `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=N`
    to the `XLA_FLAGS` environment variable, which XLA reads when JAX starts its backend.
    An option already in `XLA_FLAGS` is left as it is. On a GPU the option is harmless
    and has no effect.

    **Arguments:**

    - `byte_threshold`: loops that read and write fewer bytes than this per iteration
      become one kernel (default 1 MiB).

    **Returns:** True if the option is in effect for this process, False if JAX had
    already started its backend without it (a `RuntimeWarning` then says how to set it).
    """
    if isinstance(byte_threshold, bool) or not isinstance(byte_threshold, int) or byte_threshold < 1:
        raise InputError(f"byte_threshold = {byte_threshold!r} is out of range; valid range is integers >= 1")
    flags = os.environ.get("XLA_FLAGS", "")
    if loop_kernel_bytes(flags) is not None:
        return True
    if not _add(flags, byte_threshold):
        warnings.warn(
            "jaxunilat.use_loop_kernels() came after JAX started its backend, so it has no effect "
            f"in this process; call it before the first JAX computation, or start Python with "
            f"XLA_FLAGS='{_EXTRA}{OPTION}={byte_threshold}'.",
            RuntimeWarning,
            stacklevel=2,
        )
        return False
    return True


def _loop_setting(flags: str, byte_threshold: int) -> str:
    """`flags` with the loop-kernel option added (to an existing backend-options list,
    if there is one)."""
    setting = f"{OPTION}={byte_threshold}"
    if _EXTRA in flags:
        return flags.replace(_EXTRA, f"{_EXTRA}{setting},", 1)
    return f"{flags} {_EXTRA}{setting}".strip()


def add_xla_flags(flags: str) -> bool:
    """Set `XLA_FLAGS` to `flags` if JAX has not started its backend yet (XLA reads the
    variable once, then); True if it was set."""
    if _backend_started():
        return False
    os.environ["XLA_FLAGS"] = flags
    return True
