"""How `jax.vmap` batches a solve: one row at a time on a CPU, in lockstep elsewhere.

JAX batches a `while` loop by running every row in lockstep: the loop runs until the
last row is done, each iteration executes every branch of its `cond`/`switch` for all
rows and selects per row, and every buffer write touches all rows. The event mode's
loop is mostly branches (flight or contact, closed form or Runge–Kutta, event location,
accept or reject), and the adaptive solvers' rows take different numbers of steps, so
on a CPU, which has no wide parallel hardware to spend on the extra work, a vmapped
solve costs about twice as much per row as the same rows one after another (each row
stops at its own last step and runs only its own branch). On a GPU lockstep batching is
what fills the device.

`rowwise` therefore gives the solve a custom batching rule
(`jax.custom_batching.custom_vmap`): under `jax.vmap` it runs `jax.lax.map` over the
batched rows, the unbatched arguments shared, so `jax.jit(jax.vmap(f))` costs what
`sweep(f, ..., batch_size=1)` does. Nested `vmap`s nest the maps (the map's body calls
the rule's function again, so an outer `vmap` meets the rule too). Which rule applies is
a static choice made when the solve is traced, `batching_mode()`: `"rows"` on a CPU,
`"batch"` (plain `jax.vmap`, the solve left unwrapped) on other backends; the
environment variable `JAXUNILAT_VMAP` (`rows` or `batch`) forces one, for tests and
comparisons.

Evaluation (one call, or one row of the map) runs the solve inside a one-iteration
`while` loop (`in_one_loop`), which XLA:CPU compiles into one kernel under
`use_loop_kernels`: outside it the program is a handful of thunks, which XLA runs one
after the other on the calling thread instead of as a task graph on its thread pool.

Autodiff: a `custom_vmap` function has a JVP rule (the JVP of its rule), but JAX can
neither partially evaluate nor transpose it, so it supports forward mode only.

- `autodiff="forward"`: a `jax.custom_jvp` around it whose rule is the plain solve's own
  `jax.jvp`. Evaluation runs row by row; `jax.jvp` and `jax.jacfwd`, inside or outside
  `jax.vmap`, batch the differentiated solve in lockstep (values unchanged). Where only
  tangents are batched (JAX's JVP of the rule), the rule calls the plain solve, since
  calling itself there would recurse.
- `autodiff="reverse"`: a `jax.custom_vjp` around it whose forward and backward
  passes are the plain solve's own `jax.vjp` (the checkpointed loop's, so no extra
  solve). Evaluation runs row by row; `jax.grad` and `jax.vjp`, inside or outside
  `jax.vmap`, batch the differentiated solve in lockstep as before (their values are
  unchanged), because residuals of a `custom_vmap` function cannot carry the
  pullback's structure across the rows' traces. Reverse mode already refuses
  `jax.jvp` (the checkpointed loop is a `custom_vjp`), so nothing is lost.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.extend.core import jaxpr_as_fun, jaxprs_in_params

from .._internal._errors import InputError

#: The environment variable that forces a batching rule: "rows" or "batch".
ENV = "JAXUNILAT_VMAP"
MODES = ("rows", "batch")


def batching_mode() -> str:
    """The batching rule for solves traced now: `JAXUNILAT_VMAP` if set, else `"rows"`
    on a CPU backend and `"batch"` on others."""
    forced = os.environ.get(ENV, "")
    if forced not in _RESOLVED:
        mode = forced.strip().lower()
        if mode and mode not in MODES:
            raise InputError(f"{ENV} = {forced!r} is not supported; valid: {', '.join(MODES)} (or unset)")
        _RESOLVED[forced] = mode or ("rows" if jax.default_backend() == "cpu" else "batch")
    return _RESOLVED[forced]


#: `batching_mode()` by the value of `JAXUNILAT_VMAP` (it runs on every `simulate` call).
_RESOLVED: dict[str, str] = {}


def rowwise(fn: Callable) -> Callable:
    """`fn` (positional array pytrees to a pytree) whose `jax.vmap` is a `lax.map` over rows."""

    def call(*args):
        # The rule sees the flat leaves: JAX's JVP of a `custom_vmap` rule mistakes a
        # None in the arguments (an unset option) for a leaf.
        leaves, tree = jax.tree_util.tree_flatten(args)
        return _flat(fn, tree)(*leaves)

    return call


def in_one_loop(fn: Callable, *leaves):
    """`fn(*leaves)` (flat array leaves in, flat leaves out) computed inside a `while`
    loop of one iteration that XLA can neither remove nor hoist the work out of.

    XLA:CPU runs a program as a sequence of thunks, and once it holds more than 8 of
    them and any buffer is over 512 bytes (the outputs at 2001 save times), it runs them
    as a task graph on its thread pool, at several µs of hand-over per thunk on a busy
    machine. A loop under `use_loop_kernels`' byte threshold compiles into one kernel,
    so the whole solve is then one thunk (outside it only the loop's initial values).
    The trip count passes through an optimization barrier (a known count of one lets
    XLA inline the loop) and the arguments through another one carried with the loop
    index (loop-invariant work would be hoisted out of it). `fn` is traced once; its
    jaxpr is replayed inside the loop.
    """
    closed, shapes = jax.make_jaxpr(fn, return_shape=True)(*leaves)
    out_shapes, out_tree = jax.tree_util.tree_flatten(shapes)
    replay = jaxpr_as_fun(closed)
    if _blocks_kernel(closed.jaxpr):
        # Such a loop would not be one kernel: the plain computation.
        return jax.tree_util.tree_unflatten(out_tree, replay(*leaves))
    stop = jax.lax.optimization_barrier(jnp.ones((), jnp.int32))

    def body(carry):
        i, _ = carry
        _, args = jax.lax.optimization_barrier((i, list(leaves)))
        return i + 1, replay(*args)

    init = (jnp.zeros((), jnp.int32), [jnp.zeros(s.shape, s.dtype) for s in out_shapes])
    out = jax.lax.while_loop(lambda carry: carry[0] < stop, body, init)[1]
    return jax.tree_util.tree_unflatten(out_tree, out)


#: Primitives that keep XLA:CPU from compiling a loop that holds them into one kernel
#: and that a solve may hold: a host callback (`throw=True`'s error). (Scatters and sorts
#: do too, but the solve's only scatter is in the outputs of lockstep batching, which never
#: runs inside this one-row loop.)
_NO_KERNEL = ("callback",)


def _blocks_kernel(jaxpr) -> bool:
    """Whether `jaxpr` holds, at any depth, a primitive named like one in `_NO_KERNEL`."""
    for eqn in jaxpr.eqns:
        if any(word in eqn.primitive.name for word in _NO_KERNEL):
            return True
        for sub in jaxprs_in_params(eqn.params):
            if _blocks_kernel(sub):
                return True
    return False


def _flat(fn: Callable, tree) -> Callable:
    def plain_fn(*leaves):
        return fn(*jax.tree_util.tree_unflatten(tree, leaves))

    def flat_fn(*leaves):
        return in_one_loop(plain_fn, *leaves)

    wrapped = jax.custom_batching.custom_vmap(flat_fn)

    @wrapped.def_vmap
    def rule(axis_size, in_batched, *leaves):
        del axis_size
        if not any(in_batched):
            # Only tangents batched (JAX's JVP of this rule): the plain function, which
            # JAX then batches over the tangents alone.
            out = plain_fn(*leaves)
            return out, jax.tree_util.tree_map(lambda _: False, out)
        rows = [leaf for leaf, batched in zip(leaves, in_batched, strict=True) if batched]

        def row(one):
            it = iter(one)
            return wrapped(
                *(next(it) if batched else leaf for leaf, batched in zip(leaves, in_batched, strict=True))
            )

        out = jax.lax.map(row, rows)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return wrapped


def rowwise_differentiable(fn: Callable, autodiff: str) -> Callable:
    """`rowwise(fn)` for evaluation; for derivatives `fn`'s own: its `jax.vjp` for
    `autodiff="reverse"`, its `jax.jvp` for `"forward"` (batched in lockstep)."""
    primal = rowwise(fn)
    if autodiff == "forward":

        @jax.custom_jvp
        def solve_forward(*args):
            return primal(*args)

        @solve_forward.defjvp
        def tangent(primals, tangents):
            return jax.jvp(fn, primals, tangents)

        return solve_forward

    @jax.custom_vjp
    def solve(*args):
        return primal(*args)

    def forward(*args):
        return jax.vjp(fn, *args)

    def backward(pullback, cotangent):
        return pullback(cotangent)

    solve.defvjp(forward, backward)
    return solve
