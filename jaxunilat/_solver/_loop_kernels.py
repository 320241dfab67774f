"""`use_loop_kernels`: let XLA:CPU compile each small loop into one kernel.

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
starts its CPU backend (at the first computation). `use_loop_kernels` adds the option
to `XLA_FLAGS`, so it must run before anything computes with JAX; it changes nothing
else, and results differ from the default only at rounding level. The `jaxunilat`
command line calls it first thing. It is process-wide, so the library does not call
it on import: a program that imports jaxunilat decides.
"""

from __future__ import annotations

import os
import re
import warnings

OPTION = "xla_cpu_small_while_loop_byte_threshold"
#: Loops that touch up to 1 MiB per iteration become one kernel: the event mode's loop
#: (tens of KiB per step) and each row of a per-row sweep, but not a loop vmapped over
#: thousands of rows, whose kernels amortize their launch cost over the batch anyway.
DEFAULT_BYTES = 1 << 20
_EXTRA = "--xla_backend_extra_options="


def _backend_started() -> bool:
    """Whether JAX has started a backend (after which XLA_FLAGS is no longer read)."""
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

    The event mode's step loop then runs about 10× faster and compiles about a quarter
    faster; results change only at rounding level (about 1e-12 m on Table 1's examples).
    Call it before the first JAX computation of the process (right after the imports):
    it adds `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=N` to
    the `XLA_FLAGS` environment variable, which XLA reads when JAX starts its backend.
    An option already in `XLA_FLAGS` is left as it is. On a GPU the option is harmless
    and has no effect.

    **Arguments:**

    - `byte_threshold`: loops that read and write fewer bytes than this per iteration
      become one kernel (default 1 MiB).

    **Returns:** True if the option is in effect for this process, False if JAX had
    already started its backend without it (a `RuntimeWarning` then says how to set it).
    """
    if isinstance(byte_threshold, bool) or not isinstance(byte_threshold, int) or byte_threshold < 1:
        raise ValueError(f"byte_threshold = {byte_threshold!r} is out of range; valid range is integers >= 1")
    flags = os.environ.get("XLA_FLAGS", "")
    if loop_kernel_bytes(flags) is not None:
        return True
    if not add_xla_flags(_loop_setting(flags, byte_threshold)):
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
