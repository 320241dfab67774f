"""identify: fit contact stiffness κ and damping k_r to rebound data with jaxunilat.

The identification of [K90 §6]: bounce data (position traces, impact times, apex
heights) in, κ and k_r with honest uncertainty out.

Note: PyPI's `identify` (a pre-commit dependency) has the same import name; install
jaxunilat in a dedicated virtual environment.
"""

import jaxunilat as _jaxunilat  # noqa: F401  (enables float64)

from ._data import (  # noqa: E402
    Dataset as Dataset,
    load_dataset as load_dataset,
    write_dataset as write_dataset,
)
from ._export import (  # noqa: E402
    DEFAULT_IMPEDANCE as DEFAULT_IMPEDANCE,
    MujocoContact as MujocoContact,
    mujoco_contact as mujoco_contact,
)
from ._fit import (  # noqa: E402
    METHODS as METHODS,
    default_optimizer as default_optimizer,
    fit as fit,
)
from ._import import (  # noqa: E402
    ImplausibleRecording as ImplausibleRecording,
    ImportResult as ImportResult,
    RatioChain as RatioChain,
    Rejected as Rejected,
    bounce_problems as bounce_problems,
    ratio_chain as ratio_chain,
)
from ._import_audio import (  # noqa: E402
    OnsetDetection as OnsetDetection,
    WavAudio as WavAudio,
    detect_onsets as detect_onsets,
    import_wav as import_wav,
    plot_detection as plot_detection,
    read_wav as read_wav,
)
from ._import_tables import (  # noqa: E402
    import_phyphox as import_phyphox,
    import_video as import_video,
    plot_table_import as plot_table_import,
)
from ._plot import plot_fit as plot_fit, plot_restitution_of_fit as plot_restitution_of_fit  # noqa: E402
from ._problem import NUISANCE as NUISANCE, PARAMETERS as PARAMETERS  # noqa: E402
from ._qualify import (  # noqa: E402
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
from ._result import FitResult as FitResult  # noqa: E402

# Restitution per bounce and per contact law (e against impact speed).
# isort: split
from ._plot_restitution import plot_restitution as plot_restitution  # noqa: E402
from ._restitution import (  # noqa: E402
    BounceRestitution as BounceRestitution,
    bounce_restitution as bounce_restitution,
    hunt_crossley_from_restitution as hunt_crossley_from_restitution,
    law_contact_time as law_contact_time,
    law_restitution as law_restitution,
)
