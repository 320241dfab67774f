"""The physics: models (the ball, the coupling), contact laws, Heaviside options, and
the closed forms of free flight and of a ball at rest on a wall.

A model is an `equinox.Module` whose parameters are traced leaves and whose structure
(walls present, drag on or off, the contact law, the Heaviside option) is static. It
offers a vector field to the time-stepping solvers and a smooth-region view (switching
functions, region vector fields, closed-form flight and rest) to the event mode. The
contract is declared in `_model`: `AbstractModel` and one abstract capability base per
optional part of the engine, which the solvers test with `isinstance`.
"""

from ._ball import (
    PAPER_DRAG as PAPER_DRAG,
    PAPER_GAP as PAPER_GAP,
    PAPER_GRAVITY as PAPER_GRAVITY,
    PAPER_MASS as PAPER_MASS,
    TABLE1 as TABLE1,
    Ball as Ball,
    ball_state as ball_state,
)
from ._contact import (
    AbstractContactLaw as AbstractContactLaw,
    ClampedKelvinVoigt as ClampedKelvinVoigt,
    HuntCrossley as HuntCrossley,
    KelvinVoigt as KelvinVoigt,
    NoClosedFormError as NoClosedFormError,
    clearance_force as clearance_force,
    contact_time as contact_time,
    damping_ratio as damping_ratio,
    hunt_crossley_contact_time as hunt_crossley_contact_time,
    parameters_from_restitution as parameters_from_restitution,
    restitution as restitution,
    symmetric_clearance_force as symmetric_clearance_force,
)
from ._coupling import TABLE2 as TABLE2, Coupling as Coupling
from ._heaviside import (
    AbstractHeaviside as AbstractHeaviside,
    Exact as Exact,
    ExactHeavisideGradientWarning as ExactHeavisideGradientWarning,
    Logistic as Logistic,
    Softplus as Softplus,
    heaviside as heaviside,
)
from ._model import (
    AbstractCanRest as AbstractCanRest,
    AbstractClosedFormFlight as AbstractClosedFormFlight,
    AbstractContactModel as AbstractContactModel,
    AbstractKinkedObservable as AbstractKinkedObservable,
    AbstractModel as AbstractModel,
    AbstractSwitchedModel as AbstractSwitchedModel,
)
