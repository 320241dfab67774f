"""identify: fit contact stiffness κ and damping k_r to rebound data with jaxunilat.

The identification of [K90 §6]: bounce data (position traces, impact times, apex
heights) in, κ and k_r with honest uncertainty out.

Note: PyPI's `identify` (a pre-commit dependency) has the same import name; install
jaxunilat in a dedicated virtual environment.
"""

import jaxunilat as _jaxunilat  # noqa: F401  (enables float64)

from . import plot as plot  # noqa: E402
from ._apply._export import (  # noqa: E402
    DEFAULT_IMPEDANCE as DEFAULT_IMPEDANCE,
    MujocoContact as MujocoContact,
    mujoco_contact as mujoco_contact,
)
from ._apply._qualify import (  # noqa: E402
    DEFAULT_DRAG as DEFAULT_DRAG,
    DEFAULT_SAMPLES as DEFAULT_SAMPLES,
    ITTF_DROP as ITTF_DROP,
    ITTF_MASS as ITTF_MASS,
    ITTF_MAX as ITTF_MAX,
    ITTF_MIN as ITTF_MIN,
    QualifyResult as QualifyResult,
    qualify as qualify,
    qualify_fit as qualify_fit,
    rebound_height as rebound_height,
)
from ._data._balls import (  # noqa: E402
    AIR_DENSITY as AIR_DENSITY,
    BALLS as BALLS,
    SPHERE_DRAG_COEFFICIENT as SPHERE_DRAG_COEFFICIENT,
    BallPreset as BallPreset,
    BallSpec as BallSpec,
    ball_spec as ball_spec,
    sphere_drag as sphere_drag,
)
from ._data._format import (  # noqa: E402
    Dataset as Dataset,
    load_dataset as load_dataset,
    write_dataset as write_dataset,
)
from ._data._import import (  # noqa: E402
    ImplausibleRecording as ImplausibleRecording,
    ImportResult as ImportResult,
    RatioChain as RatioChain,
    Rejected as Rejected,
    bounce_problems as bounce_problems,
    ratio_chain as ratio_chain,
)
from ._data._import_audio import (  # noqa: E402
    OnsetDetection as OnsetDetection,
    WavAudio as WavAudio,
    detect_onsets as detect_onsets,
    import_wav as import_wav,
    read_wav as read_wav,
)
from ._data._import_phyphox import import_phyphox as import_phyphox  # noqa: E402
from ._data._import_video import import_video as import_video  # noqa: E402
from ._fit._problem import NUISANCE as NUISANCE, PARAMETERS as PARAMETERS  # noqa: E402
from ._fit._restitution import (  # noqa: E402
    BounceRestitution as BounceRestitution,
    bounce_restitution as bounce_restitution,
    hunt_crossley_from_restitution as hunt_crossley_from_restitution,
    law_contact_time as law_contact_time,
    law_restitution as law_restitution,
)
from ._pipeline import (  # noqa: E402
    METHODS as METHODS,
    default_optimizer as default_optimizer,
    fit as fit,
)
from ._report._result import FitResult as FitResult  # noqa: E402

#: The figures' old top-level names, kept one release as deprecated aliases of `identify.plot`.
_MOVED_TO_PLOT = (
    "plot_detection",
    "plot_fit",
    "plot_restitution",
    "plot_restitution_of_fit",
    "plot_table_import",
)


def __getattr__(name: str):
    """`identify.plot_fit` and the other figures: deprecated aliases of `identify.plot.*`."""
    if name in _MOVED_TO_PLOT:
        import warnings

        warnings.warn(
            f"identify.{name} is deprecated and will be removed in the next release; use identify.plot.{name}",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(plot, name)
    raise AttributeError(f"module 'identify' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_MOVED_TO_PLOT])
