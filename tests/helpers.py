"""Shared solver settings for the tests.

Every JAX simulation in this suite uses the same outputs, number of samples and solver
name per solver, so that `simulate` compiles once per model structure (parameter values,
y0, t1, dt and tolerances are traced and do not retrace).
"""

import os
import threading

import numpy as np

import jaxunilat

#: The outputs and sample count that all trajectory tests share (one compile per structure).
OUTPUTS = ("x", "v", "energy")
SAMPLES = 2001
#: Tsit5 tolerance of the accuracy tests.
TOL = 1e-10
#: RK4's static step budget, shared so that every dt uses the same compile.
RK4_MAX_STEPS = 200_016
#: The paper's initial state [K90 §5.1]: x(0) = −a, v(0) = −1/k.
PAPER_Y0 = (-0.4, -1.0 / 0.122)


def tsit5(model, y0, t1, *, tol=TOL, ts=None, throw=True):
    """Tsit5 (PID) with the shared outputs and sample count."""
    return jaxunilat.simulate(
        model,
        np.asarray(y0, float),
        t1,
        rtol=tol,
        atol=tol,
        samples=SAMPLES,
        ts=ts,
        outputs=OUTPUTS,
        throw=throw,
    )


def rk4(model, y0, t1, dt, **kwargs):
    """Classic RK4 with the shared outputs, sample count and step budget (throw=False)."""
    return jaxunilat.simulate(
        model,
        np.asarray(y0, float),
        t1,
        solver="rk4",
        dt=dt,
        max_steps=RK4_MAX_STEPS,
        samples=SAMPLES,
        outputs=OUTPUTS,
        throw=False,
        **kwargs,
    )


def arrays(sol, *names):
    """The named outputs of a Solution as NumPy arrays."""
    return tuple(np.asarray(sol.ys[n]) for n in names)


def fifo_errors(read, fifo, timeout: float = 20.0) -> list[str]:
    """The `ValueError` messages of `read(fifo)` on a FIFO, in a thread: a reader that waits
    for a writer (a hang) is given an empty one and the test fails."""
    import pytest

    errors = []

    def run():
        try:
            read(fifo)
        except ValueError as err:
            errors.append(str(err))

    reader = threading.Thread(target=run, daemon=True)
    reader.start()
    reader.join(timeout=timeout)
    if reader.is_alive():  # it waits for a writer: give it one (an empty one) and fail
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(timeout=timeout)
        pytest.fail("reading a FIFO waited for a writer")
    return errors
