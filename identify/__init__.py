"""jaxunilat.identify: fit contact stiffness κ and damping k_r to rebound data.

The identification of [K90 §6]: bounce data (position traces, impact times, apex
heights) in, κ and k_r with honest uncertainty out. Import it as
`from jaxunilat import identify`; it is a subpackage of jaxunilat (its source lives in
the repository's top-level `identify/` folder), so nothing named `identify` is
installed beside jaxunilat and PyPI's `identify` (a pre-commit dependency) can share an
environment with it.

Each public name is imported from its module when first used, so that the command line's
`jaxunilat identify --help` imports no JAX, optax or fit.
"""

import jaxunilat as _jaxunilat  # noqa: F401  (float64, before any JAX import)
from jaxunilat._internal import lazy_names

#: The namespaces (subpackages), imported when first used.
_NAMESPACES = ("plot",)
#: Each public name, and the module of this package that defines it.
_PUBLIC = {
    "DEFAULT_IMPEDANCE": "._apply._export",
    "MujocoContact": "._apply._export",
    "mujoco_contact": "._apply._export",
    "DEFAULT_DRAG": "._apply._qualify",
    "DEFAULT_SAMPLES": "._apply._qualify",
    "ITTF_DROP": "._apply._qualify",
    "ITTF_MASS": "._apply._qualify",
    "ITTF_MAX": "._apply._qualify",
    "ITTF_MIN": "._apply._qualify",
    "QualifyResult": "._apply._qualify",
    "qualify": "._apply._qualify",
    "qualify_fit": "._apply._qualify",
    "rebound_height": "._apply._qualify",
    "AIR_DENSITY": "._data._balls",
    "BALLS": "._data._balls",
    "SPHERE_DRAG_COEFFICIENT": "._data._balls",
    "BallPreset": "._data._balls",
    "BallSpec": "._data._balls",
    "ball_spec": "._data._balls",
    "sphere_drag": "._data._balls",
    "Dataset": "._data._format",
    "load_dataset": "._data._format",
    "write_dataset": "._data._format",
    "ImplausibleRecording": "._data._import",
    "ImportResult": "._data._import",
    "RatioChain": "._data._import",
    "Rejected": "._data._import",
    "bounce_problems": "._data._import",
    "ratio_chain": "._data._import",
    "OnsetDetection": "._data._import_audio",
    "WavAudio": "._data._import_audio",
    "detect_onsets": "._data._import_audio",
    "import_wav": "._data._import_audio",
    "read_wav": "._data._import_audio",
    "import_phyphox": "._data._import_phyphox",
    "import_video": "._data._import_video",
    "NUISANCE": "._fit._problem",
    "PARAMETERS": "._fit._problem",
    "BounceRestitution": "._fit._restitution",
    "bounce_restitution": "._fit._restitution",
    "hunt_crossley_from_restitution": "._fit._restitution",
    "law_contact_time": "._fit._restitution",
    "law_restitution": "._fit._restitution",
    "METHODS": "._pipeline",
    "default_optimizer": "._pipeline",
    "fit": "._pipeline",
    "FitResult": "._report._result",
    "Estimate": "._fit._estimate",
}
__all__ = sorted([*_NAMESPACES, *_PUBLIC])


__getattr__, __dir__ = lazy_names(__name__, _PUBLIC, _NAMESPACES)
