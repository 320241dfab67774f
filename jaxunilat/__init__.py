"""jaxunilat: differentiable JAX simulation of mechanical systems with unilateral constraints.

Implements Kukla, Posiadała, Skalmierski & Tylikowski (1990), "Dynamics problem of
mechanical systems with unilateral constraints" [K90]: a table-tennis ball between two
rackets with air drag, and a rolling-mill coupling with clearance, with penalty contact
written with Heaviside functions.

The top level holds the core: models, contact laws, Heaviside options, `simulate`, its
`Solution` and `Status`, observations, `sweep`, `use_loop_kernels` and
`enable_compilation_cache`. Studies, figures, the paper's reproduction and debugging
helpers are namespaces: `jaxunilat.analysis`, `jaxunilat.plot`, `jaxunilat.paper`,
`jaxunilat.debug`; the identification of contact parameters is `jaxunilat.identify`.

Importing the package enables float64 in JAX; it never imports matplotlib or scipy. Each
public name is imported from its module when first used, so `import jaxunilat` itself is
light (the command line's `--help` imports no JAX): float64 is enabled through the
`JAX_ENABLE_X64` environment variable, which JAX reads when it is imported (inherited by
child processes, as `XLA_FLAGS` is), or at once where JAX was imported first. It also lets XLA:CPU compile each small loop into one kernel (the event mode's steps run
about 10× faster): before JAX starts its backend, it adds
`--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1048576` to the
`XLA_FLAGS` environment variable (inherited by child processes). Set
`JAXUNILAT_NO_LOOP_KERNELS=1` to keep XLA's defaults. Import jaxunilat before the first
JAX computation: a backend already started cannot take the option, and the first
`simulate` then warns once with the fix. `use_loop_kernels()` sets it explicitly.
"""

import os
import sys

from ._internal._lazy import lazy_names
from ._internal._loop_kernels import apply_on_import as _apply_loop_kernels


def _enable_float64() -> None:
    """Float64 in JAX: now if JAX is imported already, else when it is (`JAX_ENABLE_X64`)."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


_enable_float64()
# Before anything computes: XLA reads XLA_FLAGS when JAX starts its backend.
_apply_loop_kernels()

#: The namespaces (subpackages), imported when first used.
_NAMESPACES = ("analysis", "debug", "identify", "paper", "plot")
#: Each public name of the top level, and the module that defines it.
_PUBLIC = {
    "read_csv": "._internal._io",
    "write_csv": "._internal._io",
    "PAPER_DRAG": "._models",
    "PAPER_GAP": "._models",
    "PAPER_GRAVITY": "._models",
    "PAPER_MASS": "._models",
    "TABLE1": "._models",
    "TABLE2": "._models",
    "AbstractContactLaw": "._models",
    "AbstractHeaviside": "._models",
    "AbstractModel": "._models",
    "Ball": "._models",
    "ClampedKelvinVoigt": "._models",
    "Coupling": "._models",
    "Exact": "._models",
    "ExactHeavisideGradientWarning": "._models",
    "HuntCrossley": "._models",
    "KelvinVoigt": "._models",
    "Logistic": "._models",
    "NoClosedFormError": "._models",
    "Softplus": "._models",
    "ball_state": "._models",
    "clearance_force": "._models",
    "contact_time": "._models",
    "damping_ratio": "._models",
    "heaviside": "._models",
    "hunt_crossley_contact_time": "._models",
    "parameters_from_restitution": "._models",
    "restitution": "._models",
    "symmetric_clearance_force": "._models",
    "CONTACT_COLUMNS": "._solver",
    "IMPACT_COLUMNS": "._solver",
    "RK4": "._solver",
    "EventRecord": "._solver",
    "Solution": "._solver",
    "Status": "._solver",
    "UncheckedStepWarning": "._solver",
    "apexes": "._solver",
    "contact_table": "._solver",
    "impact_table": "._solver",
    "impact_times": "._solver",
    "simulate": "._solver",
    "sweep": "._solver",
    "use_loop_kernels": "._internal._loop_kernels",
    "enable_compilation_cache": "._internal._compilation_cache",
}
__all__ = sorted([*_NAMESPACES, *_PUBLIC])


#: Names that lived at the top level before the namespaces: each still works, as an
#: alias of the namespace's name (`jaxunilat.plot_ball` is `jaxunilat.plot.plot_ball`).
_ALIASES = {
    "plot_ball": "plot",
    "save_figure": "plot",
    "plot_coupling": "plot",
    "plot_impact_forces": "plot",
    "reproduce": "paper",
    "SensitivityResult": "analysis",
    "ball_sensitivity": "analysis",
    "coupling_sensitivity": "analysis",
    "TangentCoupling": "analysis",
    "ftle": "analysis",
    "GradientGrowth": "analysis",
    "gradient_growth": "analysis",
    "trace_counts": "debug",
    "loop_kernel_bytes": "debug",
}


_lazy_getattr, __dir__ = lazy_names(__name__, _PUBLIC, _NAMESPACES)


def __getattr__(name: str):
    """A public name or namespace, imported when first used (`_PUBLIC`, `_NAMESPACES`), or
    an old top-level alias of a namespace's name (`_ALIASES`)."""
    if name in _ALIASES:
        return getattr(_lazy_getattr(_ALIASES[name]), name)
    return _lazy_getattr(name)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jaxunilat")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


__version__ = _version()
