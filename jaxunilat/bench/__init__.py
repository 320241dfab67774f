"""The benchmark behind `jaxunilat bench`, for notebooks: run it, draw its figures, print
its goals, and the scipy reference it measures errors against.

`run_bench(size)` returns what `jaxunilat bench` writes to `bench.json`;
`work_precision(size)` runs only its work–precision section. `load(path)` reads a
`bench.json` (files written before the goals had names, keyed P1–P5 and P7–P10, come
back with today's keys: `upgrade`); `GOALS` holds each goal's target and unit.
Rows registered by other packages (entry points of the group `jaxunilat.bench`) find the
bundled data sets with `jaxunilat._internal.bundled_data`. The peers and the reference need scipy
(the `bench` extra); importing this module does not load it.
"""

from .._bench._goals import GOALS as GOALS, OLD_KEYS as OLD_KEYS, load as load, upgrade as upgrade
from .._bench._main import (
    SIZES as SIZES,
    Size as Size,
    goal_table as goal_table,
    run_bench as run_bench,
    work_precision as work_precision,
)
from .._bench._peers import Params as Params, reference as reference
from .._bench._plot import (
    throughput_figure as throughput_figure,
    work_precision_figure as work_precision_figure,
)
