"""`jaxunilat bench`: work against precision, throughput, gradients, peers (scipy, and
a compiled Numba loop where installed), the goals measured on the users' own code, the
rows other packages register (entry-point group `jaxunilat.bench`), and the plots.

Measures only; the goals (keyed by what they measure) and their targets are in `_goals`.
"""

from ._main import run_bench as run_bench
