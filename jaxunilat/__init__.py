"""jaxunilat: differentiable JAX simulation of mechanical systems with unilateral constraints.

Implements Kukla, Posiadała, Skalmierski & Tylikowski (1990), "Dynamics problem of
mechanical systems with unilateral constraints" [K90]: a table-tennis ball between two
rackets with air drag, and a rolling-mill coupling with clearance, with penalty contact
written with Heaviside functions.

The top level holds the core: models, contact laws, Heaviside options, `simulate`, its
`Solution` and `Status`, observations, `sweep`, `use_loop_kernels` and
`use_compilation_cache`. Studies, figures,
the paper's reproduction and debugging helpers are namespaces: `jaxunilat.analysis`,
`jaxunilat.plot`, `jaxunilat.paper`, `jaxunilat.debug`.

Importing the package enables float64 in JAX; it never imports matplotlib or scipy. It
also lets XLA:CPU compile each small loop into one kernel (the event mode's steps run
about 10× faster): before JAX starts its backend, it adds
`--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1048576` to the
`XLA_FLAGS` environment variable (inherited by child processes). Set
`JAXUNILAT_NO_LOOP_KERNELS=1` to keep XLA's defaults. Import jaxunilat before the first
JAX computation: a backend already started cannot take the option, and the first
`simulate` then warns once with the fix. `use_loop_kernels()` sets it explicitly.
"""

import jax

jax.config.update("jax_enable_x64", True)

from ._solver._loop_kernels import apply_on_import as _apply_loop_kernels  # noqa: E402

# Before anything computes: XLA reads XLA_FLAGS when JAX starts its backend.
_apply_loop_kernels()

from . import analysis as analysis, debug as debug, paper as paper, plot as plot  # noqa: E402
from ._models import (  # noqa: E402
    PAPER_DRAG as PAPER_DRAG,
    PAPER_GAP as PAPER_GAP,
    PAPER_GRAVITY as PAPER_GRAVITY,
    PAPER_MASS as PAPER_MASS,
    TABLE1 as TABLE1,
    TABLE2 as TABLE2,
    AbstractContactLaw as AbstractContactLaw,
    AbstractHeaviside as AbstractHeaviside,
    AbstractModel as AbstractModel,
    Ball as Ball,
    ClampedKelvinVoigt as ClampedKelvinVoigt,
    Coupling as Coupling,
    Exact as Exact,
    ExactHeavisideGradientWarning as ExactHeavisideGradientWarning,
    HuntCrossley as HuntCrossley,
    KelvinVoigt as KelvinVoigt,
    Logistic as Logistic,
    NoClosedFormError as NoClosedFormError,
    Softplus as Softplus,
    ball_state as ball_state,
    clearance_force as clearance_force,
    contact_time as contact_time,
    damping_ratio as damping_ratio,
    heaviside as heaviside,
    hunt_crossley_contact_time as hunt_crossley_contact_time,
    parameters_from_restitution as parameters_from_restitution,
    restitution as restitution,
    symmetric_clearance_force as symmetric_clearance_force,
)
from ._solver import (  # noqa: E402
    CONTACT_COLUMNS as CONTACT_COLUMNS,
    IMPACT_COLUMNS as IMPACT_COLUMNS,
    RK4 as RK4,
    EventRecord as EventRecord,
    Solution as Solution,
    Status as Status,
    UncheckedStepWarning as UncheckedStepWarning,
    apexes as apexes,
    contact_table as contact_table,
    impact_table as impact_table,
    impact_times as impact_times,
    simulate as simulate,
    sweep as sweep,
    use_loop_kernels as use_loop_kernels,
)
from .internal._compilation_cache import use_compilation_cache as use_compilation_cache  # noqa: E402
from .internal._io import read_csv as read_csv, write_csv as write_csv  # noqa: E402

#: Names that lived at the top level before the namespaces: each still works, as an
#: alias of the namespace's name (`jaxunilat.plot_ball` is `jaxunilat.plot.plot_ball`).
_ALIASES = {
    "plot_ball": plot,
    "save_figure": plot,
    "plot_coupling": plot,
    "plot_impact_forces": plot,
    "reproduce": paper,
    "SensitivityResult": analysis,
    "ball_sensitivity": analysis,
    "coupling_sensitivity": analysis,
    "TangentCoupling": analysis,
    "ftle": analysis,
    "GradientGrowth": analysis,
    "gradient_growth": analysis,
    "trace_counts": debug,
    "loop_kernel_bytes": debug,
}


def __getattr__(name: str):
    namespace = _ALIASES.get(name)
    if namespace is None:
        raise AttributeError(f"module 'jaxunilat' has no attribute {name!r}")
    return getattr(namespace, name)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jaxunilat")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


__version__ = _version()
