"""Tools for checking the compiled programs, as `equinox.debug` does for equinox.

- `trace_counts()`: how many times each jitted entry point was traced in this process
  (a test that new parameter values do not recompile counts these).
- `loop_kernel_bytes()`: the size of the CPU loop kernels compiled so far.
"""

from .._internal._loop_kernels import loop_kernel_bytes as loop_kernel_bytes
from .._solver._simulate import trace_counts as trace_counts
