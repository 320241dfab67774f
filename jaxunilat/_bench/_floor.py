"""The loop floor: what one iteration of a compiled loop costs on this CPU, beside what
one step attempt of the event mode costs, alone and in a vmapped batch.

`loop_floor()` puts the event mode's per-attempt cost next to the cheapest possible
iteration of the same kind of loop (`lax.while_loop`, compiled into one kernel under
`use_loop_kernels`), so that a reader can tell how much of a step is loop machinery and
how much is the step itself.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

#: Table 1 example 2 (κ = 1e4 N/m, k_r = 0.2 N·s/m) from the paper's initial state.
_Y0 = (-0.4, -1.0 / 0.122)
_TOL = 1e-10
_PIECE = "dopri8"
_ROWS = 1000


def _median_wall(fn, repeats: int) -> float:
    """Median wall time of `repeats` calls of `fn` after one warm-up call, s."""
    fn()
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - start)
    return statistics.median(walls)


def _empty_loop():
    """A jitted `lax.while_loop` of n iterations (n traced) whose body is one add."""
    import jax
    import jax.numpy as jnp

    def loop(n, x):
        def body(carry):
            i, acc = carry
            return i + 1, acc + x

        return jax.lax.while_loop(lambda carry: carry[0] < n, body, (jnp.zeros_like(n), jnp.zeros_like(x)))[1]

    return jax.jit(loop), jax.jit(jax.vmap(loop))


def _empty_iteration_ns(repeats: int) -> tuple[float, float]:
    """(ns per iteration of the empty loop, ns per row-iteration vmapped over `_ROWS`
    rows), each from the difference of two trip counts (the call's fixed cost cancels)."""
    import jax
    import jax.numpy as jnp

    single, batched = _empty_loop()
    x, xs = jnp.asarray(1.0), jnp.ones(_ROWS)

    def per_iteration(fn, arg, short, long, rows):
        walls = {}
        for n in (short, long):
            count = jnp.full(np.shape(arg), n, dtype=jnp.int32)
            walls[n] = _median_wall(lambda count=count: jax.block_until_ready(fn(count, arg)), repeats)
        return 1e9 * (walls[long] - walls[short]) / ((long - short) * rows)

    return per_iteration(single, x, 1_000, 201_000, 1), per_iteration(batched, xs, 10, 1_010, _ROWS)


def _attempt_ns(repeats: int) -> tuple[float, float, int, float]:
    """(ns per step attempt of one event-mode solve, from two spans of one compiled
    solve; ns per row-attempt of a vmapped batch of `_ROWS` κ values; the attempts of
    the full span; its wall time, s)."""
    import jax
    import jax.numpy as jnp

    from .._models._ball import Ball
    from .._solver._simulate import simulate

    y0 = jnp.asarray(_Y0)
    kw = dict(
        solver="event", piece_solver=_PIECE, rtol=_TOL, atol=_TOL, samples=2, outputs=("x",), throw=False
    )

    def solve(kappa, t1):
        sol = simulate(Ball.table1(2, kappa=kappa), y0, t1, **kw)
        return sol.ys["x"], sol.num_steps

    one = jax.jit(solve)
    batch = jax.jit(jax.vmap(solve, in_axes=(0, None)))
    kappa = jnp.asarray(1e4)
    walls, steps = {}, {}
    for t1 in (0.5, 2.0):
        span = jnp.asarray(t1)
        steps[t1] = int(one(kappa, span)[1])
        walls[t1] = _median_wall(lambda span=span: jax.block_until_ready(one(kappa, span)), repeats)
    per_attempt = 1e9 * (walls[2.0] - walls[0.5]) / (steps[2.0] - steps[0.5])
    kappas = jnp.asarray(10 ** np.linspace(np.log10(5e3), np.log10(2e4), _ROWS))
    span = jnp.asarray(2.0)
    total = int(jnp.sum(batch(kappas, span)[1]))
    wall = _median_wall(lambda: jax.block_until_ready(batch(kappas, span)), max(repeats // 3, 2))
    return per_attempt, 1e9 * wall / total, steps[2.0], walls[2.0]


def loop_floor(repeats: int = 7) -> dict:
    """Measure, on this CPU: the cost of an empty `lax.while_loop` iteration, alone and
    vmapped over 1000 rows, and the event mode's cost per step attempt, alone and per
    row-attempt in a vmapped batch of 1000 κ values (Table 1 example 2, Dopri8 pieces,
    tol 1e-10, 2 save times so that the outputs stay out of it).

    **Returns:** a dict of figures in ns (`empty_iteration_ns`,
    `empty_row_iteration_vmap_ns`, `event_attempt_ns`, `event_row_attempt_vmap_ns`), the
    single solve's attempts and wall time, and `how` (how they were measured). A few
    seconds, most of it compilation.
    """
    empty, empty_vmap = _empty_iteration_ns(repeats)
    attempt, row_attempt, attempts, wall = _attempt_ns(repeats)
    return {
        "empty_iteration_ns": empty,
        "empty_row_iteration_vmap_ns": empty_vmap,
        "event_attempt_ns": attempt,
        "event_row_attempt_vmap_ns": row_attempt,
        "event_attempts": attempts,
        "event_wall_s": wall,
        "how": (
            f"median wall of {repeats} calls after a warm-up; empty loop: a jitted lax.while_loop "
            f"with a traced trip count and one add per iteration, the difference between 201000 and "
            f"1000 iterations (vmapped: {_ROWS} rows, 1010 and 10 iterations) over the extra "
            f"iterations; event mode: Table 1 example 2, {_PIECE} pieces, tol {_TOL:g}, 2 save "
            f"times, spans [0, 0.5] and [0, 2] s of one compiled solve, the wall difference over "
            f"the difference of the solver's step attempts; vmapped: {_ROWS} kappa values in "
            f"[5e3, 2e4] N/m over [0, 2] s, the wall over the sum of the rows' attempts"
        ),
    }
