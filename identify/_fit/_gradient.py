"""The optional gradient stage (`method="optax"`): an `optax.GradientTransformation` on
½Σ(w·r)² with forward-mode (or reverse-mode) derivatives through the event mode."""

from __future__ import annotations

import dataclasses
import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax


@functools.lru_cache(maxsize=8)
def gradient_step(optimizer, gradient: str):
    """One jitted optax step on ½Σ(w·r)² over every file (cached per optimizer and mode:
    a new jitted step for every fit would recompile the pass through the event mode).

    `gradient="forward"`: each file's Jacobian by `jax.jacfwd` through the event mode in
    forward mode (`autodiff="forward"`, one tangent per entry of z), then g = Jᵀ(w²r);
    `"reverse"`: `jax.grad` of the loss.
    """

    def file_gradient(problem, z6, w):
        if gradient == "forward":
            residuals = lambda z: problem.residuals(z)[0]  # noqa: E731
            r, jac = residuals(z6), jax.jacfwd(residuals)(z6)
            return 0.5 * jnp.sum((w * r) ** 2), jac.T @ (w**2 * r)
        loss = lambda z: 0.5 * jnp.sum((w * problem.residuals(z)[0]) ** 2)  # noqa: E731
        return jax.value_and_grad(loss)(z6)

    @eqx.filter_jit
    def step(problems, indices, weights, z, opt_state, mask):
        value, grad = jnp.zeros(()), jnp.zeros_like(z)
        for problem, index, w in zip(problems, indices, weights, strict=True):
            values, grads = jax.lax.map(lambda args: file_gradient(*args), (problem, z[index], w))
            value = value + jnp.sum(values)
            grad = grad.at[index].add(grads)
        grad = jnp.where(mask, grad, 0.0)
        updates, opt_state = optimizer.update(grad, opt_state, z)
        return optax.apply_updates(z, jnp.where(mask, updates, 0.0)), opt_state, value

    return step


def run_gradient_stage(step, opts, setup, rows, w_rows, z):
    """`opts.steps` optax iterations from z, on the rows weighted `w_rows` (the first
    window's); returns the best point seen and the count."""
    mode = "forward" if opts.gradient == "forward" else "reverse"
    problems, indices, weights = [], [], []
    for g in setup.evaluator.groups:
        problems.append(dataclasses.replace(g.problem, autodiff=mode))
        indices.append(jnp.asarray(setup.layout.index[g.files]))
        n_pad = int(np.asarray(g.problem.t_obs).shape[-1])
        w = np.zeros((len(g.files), n_pad))
        for k, f in enumerate(g.files):
            w[k, : g.rows[k]] = w_rows[rows.of_file(f)]
        weights.append(jnp.asarray(w))
    mask = np.zeros(setup.layout.size, bool)
    mask[setup.free] = True
    zj, opt_state = jnp.asarray(z), opts.optimizer.init(jnp.asarray(z))
    best, best_value = np.asarray(zj), math.inf
    for _ in range(opts.steps):
        new, opt_state, value = step(problems, indices, weights, zj, opt_state, jnp.asarray(mask))
        value = float(value)
        if value < best_value:
            best, best_value = np.asarray(zj), value
        zj = jnp.clip(new, setup.lo, setup.hi)
    return best.copy(), opts.steps
