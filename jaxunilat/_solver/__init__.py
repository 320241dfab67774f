"""The solver: `simulate` and its settings, the event engine, dense output, loop
kernels, sweeps, and the observations read off a solution.

Design notes: `README.md` in this folder.
"""

from .._internal._loop_kernels import (
    loop_kernel_bytes as loop_kernel_bytes,
    use_loop_kernels as use_loop_kernels,
)
from ._coupling_impacts import IMPACT_COLUMNS as IMPACT_COLUMNS, impact_table as impact_table
from ._event import EventRecord as EventRecord
from ._observe import (
    CONTACT_COLUMNS as CONTACT_COLUMNS,
    apexes as apexes,
    contact_table as contact_table,
    impact_times as impact_times,
)
from ._settings import RK4 as RK4
from ._simulate import (
    Solution as Solution,
    Status as Status,
    UncheckedStepWarning as UncheckedStepWarning,
    simulate as simulate,
    trace_counts as trace_counts,
)
from ._sweep import sweep as sweep
