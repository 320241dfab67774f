"""Where latency-bound work runs when the default backend is an accelerator.

A single solve is a loop of tiny steps on a 2-vector: on a GPU every step is a kernel
launch, so one `simulate` call costs tens of ms there against well under 1 ms on a CPU,
and a fit of many such calls is many times slower. Batched work (`sweep`, `jax.vmap`) is
what fills an accelerator. So when JAX's default backend is not the CPU, a concrete single
`simulate`, `identify.fit`, `identify.qualify_fit` and every command of the command line
run on the host's CPU device (`on_host`), while sweeps and solves traced by the user's own
`jax.jit`/`jax.vmap` stay where JAX puts them.

The user's placement wins: `jax.default_device(...)` (the context manager or the
`jax_default_device` setting), arrays already committed to a device, or
`JAXUNILAT_DEVICE=default` (leave everything on JAX's default backend).
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Callable, Iterator

import jax

#: The environment variable that turns the host placement off: `default` keeps JAX's
#: default device for everything; `host` (or unset) runs latency-bound work on the CPU.
ENV = "JAXUNILAT_DEVICE"
CHOICES = ("host", "default")


def host_device():
    """The CPU device that latency-bound work should run on now, or None to leave the
    placement as it is: None where the default backend is the CPU already, where the user
    set a default device (`jax.default_device`, `jax_default_device`), where
    `JAXUNILAT_DEVICE=default`, or where JAX has no CPU backend."""
    choice = os.environ.get(ENV, "").strip().lower() or "host"
    if choice not in CHOICES:
        raise ValueError(
            f"{ENV} = {os.environ.get(ENV)!r} is not supported; valid: {', '.join(CHOICES)} (or unset)"
        )
    if choice == "default" or jax.config.jax_default_device is not None:
        return None
    if jax.default_backend() == "cpu":
        return None
    try:
        return jax.local_devices(backend="cpu")[0]
    except RuntimeError:  # no CPU backend in this process
        return None


@contextlib.contextmanager
def on_host() -> Iterator[None]:
    """Inside the block, JAX's default device is the host CPU where `host_device()` says so
    (uncommitted arrays and new computations go there; committed arrays keep theirs)."""
    device = host_device()
    if device is None:
        yield
        return
    with jax.default_device(device):
        yield


def latency_bound(fn: Callable) -> Callable:
    """`fn` run inside `on_host()`: for public entry points whose work is a sequence of
    single solves (a fit, a qualification)."""

    @functools.wraps(fn)
    def placed(*args, **kwargs):
        with on_host():
            return fn(*args, **kwargs)

    return placed


def keep_placement(fn: Callable) -> Callable:
    """`fn` bound to the current default device, for a worker thread: JAX's default
    device is per thread, and a thread started inside `on_host()` would otherwise compile
    for the accelerator."""
    device = jax.config.jax_default_device
    if device is None:
        return fn

    @functools.wraps(fn)
    def placed(*args, **kwargs):
        with jax.default_device(device):
            return fn(*args, **kwargs)

    return placed
