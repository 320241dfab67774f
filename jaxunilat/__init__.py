"""jaxunilat: differentiable JAX simulation of mechanical systems with unilateral constraints.

Implements Kukla, Posiadała, Skalmierski & Tylikowski (1990), "Dynamics problem of
mechanical systems with unilateral constraints" [K90]: a table-tennis ball between two
rackets with air drag, with penalty contact written with Heaviside functions.

Importing the package enables float64 in JAX. On a CPU, call `use_loop_kernels()` before
the first computation: the event mode's step loop then compiles into one kernel (about
10× faster per step); the `jaxunilat` command line does this itself.
"""

import jax

jax.config.update("jax_enable_x64", True)

from ._ball import (  # noqa: E402
    PAPER_DRAG as PAPER_DRAG,
    PAPER_GAP as PAPER_GAP,
    PAPER_GRAVITY as PAPER_GRAVITY,
    PAPER_MASS as PAPER_MASS,
    TABLE1 as TABLE1,
    Ball as Ball,
    ball_state as ball_state,
)
from ._contact import (  # noqa: E402
    AbstractContactLaw as AbstractContactLaw,
    ClampedKelvinVoigt as ClampedKelvinVoigt,
    HuntCrossley as HuntCrossley,
    KelvinVoigt as KelvinVoigt,
    clearance_force as clearance_force,
    contact_time as contact_time,
    damping_ratio as damping_ratio,
    hunt_crossley_contact_time as hunt_crossley_contact_time,
    parameters_from_restitution as parameters_from_restitution,
    restitution as restitution,
    symmetric_clearance_force as symmetric_clearance_force,
)
from ._coupling import TABLE2 as TABLE2, Coupling as Coupling  # noqa: E402
from ._coupling_impacts import IMPACT_COLUMNS as IMPACT_COLUMNS, impact_table as impact_table  # noqa: E402
from ._event import EventRecord as EventRecord  # noqa: E402
from ._gradient_growth import GradientGrowth as GradientGrowth, gradient_growth as gradient_growth  # noqa: E402
from ._heaviside import (  # noqa: E402
    AbstractHeaviside as AbstractHeaviside,
    Exact as Exact,
    ExactHeavisideGradientWarning as ExactHeavisideGradientWarning,
    Logistic as Logistic,
    Softplus as Softplus,
    heaviside as heaviside,
)
from ._io import read_csv as read_csv, write_csv as write_csv  # noqa: E402
from ._loop_kernels import loop_kernel_bytes as loop_kernel_bytes, use_loop_kernels as use_loop_kernels  # noqa: E402
from ._lyapunov import TangentCoupling as TangentCoupling, ftle as ftle  # noqa: E402
from ._model import AbstractModel as AbstractModel  # noqa: E402
from ._observe import (  # noqa: E402
    CONTACT_COLUMNS as CONTACT_COLUMNS,
    apexes as apexes,
    contact_table as contact_table,
    impact_times as impact_times,
)
from ._plot import plot_ball as plot_ball, save_figure as save_figure  # noqa: E402
from ._plot_coupling import plot_coupling as plot_coupling, plot_impact_forces as plot_impact_forces  # noqa: E402
from ._reproduce import reproduce as reproduce  # noqa: E402
from ._sensitivity import (  # noqa: E402
    SensitivityResult as SensitivityResult,
    ball_sensitivity as ball_sensitivity,
    coupling_sensitivity as coupling_sensitivity,
)
from ._simulate import (  # noqa: E402
    Solution as Solution,
    Status as Status,
    simulate as simulate,
    trace_counts as trace_counts,
)
from ._solvers import RK4 as RK4  # noqa: E402
from ._sweep import sweep as sweep  # noqa: E402


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jaxunilat")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


__version__ = _version()
