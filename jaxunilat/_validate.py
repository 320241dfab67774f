"""Input validation at the public boundary.

Checks run only on concrete values: under `jax.jit`, `jax.vmap` or `jax.grad` the
values are tracers and are left to the runtime checks (`eqx.error_if`) of the solver.
"""

from __future__ import annotations

import math

import jax
import numpy as np


def is_concrete(value) -> bool:
    """True when `value` holds numbers now (not a tracer inside a transformation)."""
    return not isinstance(value, jax.core.Tracer)


def as_float_array(value):
    """A float64 array for a jitted call, without a device dispatch for plain numbers.

    Python and NumPy inputs become NumPy arrays (jit traces them like any array);
    JAX arrays and tracers pass through, cast to float64 only if needed.
    """
    if isinstance(value, (jax.Array, jax.core.Tracer)):
        return value if value.dtype == np.float64 else value.astype(np.float64)
    return np.asarray(value, dtype=np.float64)


def _values(value):
    return np.asarray(value, dtype=float).ravel()


def check_finite(name: str, value, *, allow_none: bool = False) -> None:
    """Raise `ValueError` if a concrete `value` holds NaN or infinity."""
    if value is None:
        if allow_none:
            return
        raise ValueError(f"{name} must be given, got None")
    if not is_concrete(value):
        return
    for v in _values(value):
        if not math.isfinite(v):
            raise ValueError(f"{name} = {v} is not finite; it must be a finite number")


def _range_text(lo, hi, lo_open, hi_open) -> str:
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    lo_txt = "-inf" if lo is None else f"{lo:g}"
    hi_txt = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_txt}, {hi_txt}{right}"


def runtime_check(
    name: str,
    value,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> tuple[str, jax.Array]:
    """The run-time twin of `check_range` for a traced value: `(message, valid)`.

    `valid` is a scalar bool array, true when every entry of `value` is finite and
    within the bounds; `message` names `name` and the valid range. `simulate` turns a
    false `valid` into `Status.INVALID_INPUT` (and, with `throw=True`, an error with
    `message`).
    """
    import jax.numpy as jnp

    v = jnp.asarray(value)
    ok = jnp.isfinite(v)
    if lo is not None:
        ok = ok & ((v > lo) if lo_open else (v >= lo))
    if hi is not None:
        ok = ok & ((v < hi) if hi_open else (v <= hi))
    suffix = f" {unit}" if unit else ""
    message = (
        f"jaxunilat.simulate: {name} is out of range (a traced value); valid range is "
        f"{_range_text(lo, hi, lo_open, hi_open)}{suffix}, finite."
    )
    return message, jnp.all(ok)


def check_range(
    name: str,
    value,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    allow_none: bool = False,
) -> None:
    """Raise `ValueError` naming `name`, the value and the valid range.

    **Arguments:**

    - `name`: the parameter's name as the user knows it.
    - `value`: a scalar or array; tracers are skipped.
    - `lo`, `hi`: bounds, `None` for unbounded.
    - `lo_open`, `hi_open`: whether the bound itself is excluded.
    - `unit`: appended to the message, e.g. `"m"`.
    """
    check_finite(name, value, allow_none=allow_none)
    if value is None or not is_concrete(value):
        return
    rng = _range_text(lo, hi, lo_open, hi_open)
    suffix = f" {unit}" if unit else ""
    for v in _values(value):
        bad = False
        if lo is not None and (v < lo or (lo_open and v == lo)):
            bad = True
        if hi is not None and (v > hi or (hi_open and v == hi)):
            bad = True
        if bad:
            raise ValueError(f"{name} = {v:g}{suffix} is out of range; valid range is {rng}{suffix}")


def check_choice(name: str, value, choices) -> None:
    """Raise `ValueError` if `value` is not one of `choices`."""
    if value not in choices:
        opts = ", ".join(repr(c) for c in choices)
        raise ValueError(f"{name} = {value!r} is not supported; choose one of {opts}")
