"""Studies built on `simulate`: parameter sensitivities, the finite-time Lyapunov
exponent (FTLE) of the coupling, and how gradients grow with the horizon.

    import jaxunilat as ju
    result = ju.analysis.ball_sensitivity(ju.Ball.table1(2), t1=1.0)
"""

from ._gradient_growth import GradientGrowth as GradientGrowth, gradient_growth as gradient_growth
from ._lyapunov import TangentCoupling as TangentCoupling, ftle as ftle
from ._sensitivity import (
    COUPLING_PARAMETERS as COUPLING_PARAMETERS,
    SensitivityResult as SensitivityResult,
    ball_sensitivity as ball_sensitivity,
    coupling_features as coupling_features,
    coupling_sensitivity as coupling_sensitivity,
)
