"""`jaxunilat bench`: work against precision, throughput, gradients, identification,
peers (scipy, and MuJoCo where installed), the user-facing goals, and the plot.

Measures only; the goals P1–P9 and their targets are in `_goals` and `_user`.
"""

from ._main import run_bench as run_bench
