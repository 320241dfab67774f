"""Input validation at the public boundary.

Checks run only on concrete values: under `jax.jit`, `jax.vmap` or `jax.grad` the
values are tracers and are left to the runtime checks (`eqx.error_if`) of the solver.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from ._errors import InputError
from ._text import shown


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


class InputTypeError(TypeError, InputError):
    """A parameter of the wrong type: a string, a complex or boolean number, `None` or
    another object where a real number (or an array of them) goes. Both a `TypeError`
    and, for code that reports any bad input as a `ValueError`, an `InputError` (a
    `ValueError`)."""


def real_number(name: str, value, *, unit: str = ""):
    """Return `value` unchanged once it is known to hold real numbers.

    Raises `InputTypeError` naming `name`, what was given and what is expected when
    `value` is `None`, a string (even one like `"1e4"`: no silent parsing), complex,
    boolean or not numeric at all. Arrays and tracers are checked by dtype; a sequence
    that NumPy cannot take (e.g. a list of tracers) is left to the conversion.
    """
    expected = "a real number" + (f" in {unit}" if unit else "") + " or an array of them"
    if isinstance(value, (jax.Array, jax.core.Tracer)):
        kind = np.dtype(value.dtype).kind
    elif value is None:
        raise InputTypeError(f"{name} = None; give {expected}")
    elif isinstance(value, (str, bytes)):
        raise InputTypeError(f"{name} = {_short(value)} is a string; give {expected}, not text")
    elif isinstance(value, int) and not isinstance(value, bool):
        if abs(value) >= 2**1024:  # beyond float64 (NumPy would make it an object array)
            raise InputError(
                f"{name} = {shown(value)} is out of range; valid range is finite float64 numbers "
                "(magnitude below about 1.8e308)"
            )
        kind = "i"
    else:
        try:
            kind = np.asarray(value).dtype.kind
        except Exception:  # e.g. a list holding tracers: jnp.asarray takes it
            return value
    what = {"c": "complex", "b": "boolean"}.get(kind, f"not numeric ({type(value).__name__})")
    if kind not in "fiu":
        raise InputTypeError(f"{name} = {_short(value)} is {what}; give {expected}")
    return value


def _short(value) -> str:
    """A repr of `value` short enough for a one-line message."""
    import reprlib

    short = reprlib.Repr()
    short.maxstring, short.maxother, short.maxlist, short.maxtuple = 40, 60, 6, 6
    return short.repr(value)


def float_field(name: str, unit: str = "", *, optional: bool = False):
    """An equinox field converter to a float64 scalar whose errors name `name`
    (`optional`: `None` passes through, e.g. an absent wall or damping term).

    A value with more than one entry (a list, an array of shape (2,), also traced) is
    refused with an `InputError` (a `ValueError`): a model holds one value per parameter, and a batch of
    models is made with `jax.vmap` or `jaxunilat.sweep` over scalar parameters (their
    rows are scalars there). A shape-(1,) or (1, 1) value is taken as its one entry.
    """
    import jax.numpy as jnp

    def convert(value):
        if value is None and optional:
            return None
        value = jnp.asarray(real_number(name, value, unit=unit), dtype=float)
        if value.ndim:
            if value.size != 1:
                shown = _short(np.asarray(value).tolist()) if is_concrete(value) else "a traced array"
                suffix = f" in {unit}" if unit else ""
                raise InputError(
                    f"{name} = {shown} has shape {tuple(value.shape)}; valid is one real number{suffix} "
                    "(shape ()); for a batch of models use jax.vmap or jaxunilat.sweep over scalar values"
                )
            value = value.reshape(())
        return value

    convert.__name__ = f"float_field_{name}"
    return convert


def _values(name, value):
    try:
        return np.asarray(real_number(name, value), dtype=float).ravel()
    except OverflowError:  # an integer beyond float64
        raise InputError(
            f"{name} = {shown(value)} is out of range; valid range is finite float64 numbers "
            "(magnitude below about 1.8e308)"
        ) from None


def check_finite(name: str, value, *, allow_none: bool = False) -> None:
    """Raise `InputError` (a `ValueError`) if a concrete `value` holds NaN or infinity."""
    if value is None:
        if allow_none:
            return
        raise InputError(f"{name} must be given, got None")
    if not is_concrete(value):
        return
    for v in _values(name, value):
        if not math.isfinite(v):
            raise InputError(f"{name} = {v} is not finite; it must be a finite number")


def _range_text(lo, hi, lo_open, hi_open) -> str:
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    lo_txt = "-inf" if lo is None else f"{lo:g}"
    hi_txt = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_txt}, {hi_txt}{right}"


def _within(v, lo, hi, lo_open, hi_open):
    """Whether `v` (a float, or an array: elementwise) lies within the bounds (NaN: no)."""
    ok = True
    if lo is not None:
        ok = ok & ((v > lo) if lo_open else (v >= lo))
    if hi is not None:
        ok = ok & ((v < hi) if hi_open else (v <= hi))
    return ok


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
    ok = jnp.isfinite(v) & _within(v, lo, hi, lo_open, hi_open)
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
    """Raise `InputError` (a `ValueError`) naming `name`, the value and the valid range.

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
    for v in _values(name, value):
        if not _within(v, lo, hi, lo_open, hi_open):
            raise InputError(f"{name} = {v:g}{suffix} is out of range; valid range is {rng}{suffix}")


def check_type(name: str, value, cls: type, expected: str) -> None:
    """Raise `InputTypeError` naming `name` unless `value` is an instance of `cls`."""
    if not isinstance(value, cls):
        raise InputTypeError(
            f"{name} = {shown(value)} ({type(value).__name__}) is not supported; give {expected}"
        )


def check_choice(name: str, value, choices) -> None:
    """Raise `InputError` (a `ValueError`) if `value` is not one of `choices`."""
    if value not in choices:
        opts = ", ".join(repr(c) for c in choices)
        raise InputError(f"{name} = {shown(value)} is not supported; choose one of {opts}")
