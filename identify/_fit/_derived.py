"""Derived quantities of a fitted point: file f's view of the joint vector, and e and
t_c (with their standard errors) for the fit's law."""

from __future__ import annotations

import functools
import math

import numpy as np

from jaxunilat import KelvinVoigt

from ._joint import contact_time_of
from ._kelvin_voigt import restitution_and_contact_time
from ._problem import LAW_MODELS, PARAMETERS
from ._uncertainty import summarize


def view(setup, z: np.ndarray, cov: np.ndarray, f: int = 0):
    """File f's z_f, the covariance of its free entries, and their indices in PARAMETERS."""
    idx = setup.layout.index[f]
    free6 = [i for i in range(len(PARAMETERS)) if idx[i] in setup.free]
    pos = [setup.free.index(idx[i]) for i in free6]
    return np.asarray(z)[idx], cov[np.ix_(pos, pos)], free6


def law_derived(setup):
    """(log κ, log k_r, mass) → (e, t_c, ∂e/∂u, ∂log t_c/∂u) for the fit's law, u = (log κ,
    log k_r).

    A law whose e and t_c do not depend on the impact speed: its closed forms (no
    gravity), Kelvin–Voigt's with exact gradients (`_kelvin_voigt`), any other's on the
    host (`xp=numpy`) with central differences. A law whose e depends on the speed: e of
    one impact at the data's typical impact speed (simulated as in `law_restitution`;
    central differences) and the undamped contact time there (`contact_time_of`).
    """
    model = LAW_MODELS[setup.law]
    if model.restitution_depends_on_speed:
        return _simulated(setup)
    if type(model) is KelvinVoigt:
        return restitution_and_contact_time
    return functools.partial(_closed_forms, model)


def _closed_forms(model, lk: float, lr: float, mass: float):
    """A speed-independent law's (e, t_c, ∂e/∂u, ∂log t_c/∂u) from its closed forms on the
    host; an impact with no rebound (e = 0, t_c = inf) has zero gradients."""

    def at(u):
        kappa, k_r = math.exp(u[0]), math.exp(u[1])
        e = float(model.restitution(kappa, k_r, mass, None, xp=np))
        return e, float(model.contact_time(kappa, k_r, mass, None, xp=np))

    u = np.array([float(lk), float(lr)])
    e, t_c = at(u)
    if not (e > 0 and math.isfinite(t_c)):
        return e, t_c, np.zeros(2), np.zeros(2)
    grad_e, grad_log_tc = np.zeros(2), np.zeros(2)
    for i in range(2):
        step = np.eye(2)[i] * _CLOSED_STEP
        (e_up, t_up), (e_down, t_down) = at(u + step), at(u - step)
        grad_e[i] = (e_up - e_down) / (2 * _CLOSED_STEP)
        grad_log_tc[i] = (math.log(t_up) - math.log(t_down)) / (2 * _CLOSED_STEP)
    return e, t_c, grad_e, grad_log_tc


def _simulated(setup):
    """A speed-dependent law's (e, t_c, ∂e/∂u, ∂log t_c/∂u) at the data's typical impact
    speed (see `law_derived`); ∂log t_c/∂u of the undamped time by central differences
    (for Hunt–Crossley, −1/(n + 1) in log κ and 0 in log k_r)."""
    law, speed, g = setup.law, setup.speed, float(setup.datasets[0].gravity)

    def derived(lk, lr, mass):
        e, ge = _simulated_restitution(law, float(lk), float(lr), float(mass), speed, g)
        t_c = contact_time_of(law, lk, lr, mass, speed)
        up, down = (contact_time_of(law, lk + d, lr, mass, speed) for d in (_CLOSED_STEP, -_CLOSED_STEP))
        return e, t_c, ge.copy(), np.array([(math.log(up) - math.log(down)) / (2 * _CLOSED_STEP), 0.0])

    return derived


#: Central-difference step (in log κ, log k_r) of a closed form's gradient.
_CLOSED_STEP = 1e-5
#: Central-difference step (in log κ, log k_r) of a simulated e's gradient.
_E_STEP = 1e-4


@functools.lru_cache(maxsize=256)
def _simulated_restitution(law: str, lk: float, lr: float, mass: float, speed: float, gravity: float):
    """The law's e at `speed` (m/s) and its gradient in (log κ, log k_r).

    The point and its four neighbours are one batch of simulated impacts
    (`law_restitution`'s program, rtol 1e-12). Cached: the files of a joint fit share κ,
    k_r and usually the mass, and every file's table asks for the same values.
    """
    from ._restitution import _impact_rows

    h = _E_STEP
    lks = lk + np.array([0.0, h, -h, 0.0, 0.0])
    lrs = lr + np.array([0.0, 0.0, 0.0, h, -h])
    e, _ = _impact_rows(law, np.exp(lks), np.exp(lrs), np.full(5, speed), mass, gravity, 1e-12)
    e = np.asarray(e, dtype=float)
    return float(e[0]), np.array([(e[1] - e[2]) / (2 * h), (e[3] - e[4]) / (2 * h)])


def derived_quantities(setup, z: np.ndarray, cov: np.ndarray, f: int = 0) -> dict:
    """The derived e and t_c entries of file f's view (see `summarize`)."""
    z6, cov6, free6 = view(setup, z, cov, f)
    mass = float(setup.datasets[f].mass)
    return summarize(z6, cov6, free6, mass, derived=law_derived(setup))[1]
