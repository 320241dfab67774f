"""Test set-up: float64, this directory on sys.path (for `reference`, `helpers`), shared fixtures."""

import os
import sys

import jax
import pytest

# The suite never reads or writes the command line's persistent compilation cache: every
# test compiles what it runs (tests/test_compilation_cache.py turns it on in a subprocess).
os.environ["JAXUNILAT_NO_CACHE"] = "1"

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from helpers import PAPER_Y0, tsit5  # noqa: E402
from reference import BallParams, scipy_reference  # noqa: E402

import jaxunilat  # noqa: E402

# The configuration users run (and it compiles faster): `import jaxunilat` sets it; the
# explicit call keeps it on with JAXUNILAT_NO_LOOP_KERNELS set. tests/test_loop_kernels.py
# checks XLA's default configuration against it.
jaxunilat.use_loop_kernels()


@pytest.fixture(scope="session")
def ref_ex2():
    """scipy DOP853 + events reference for Table 1 example 2 on [0, 2] s."""
    return scipy_reference(BallParams.table1(2), PAPER_Y0, 2.0)


@pytest.fixture(scope="session")
def sim_ex2():
    """The package's Tsit5 (exact Heaviside, tolerance 1e-10) for example 2 on [0, 2] s."""
    return tsit5(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0)
