"""Derived quantities of a fitted point: file f's view of the joint vector, and e and
t_c (with their standard errors) for the fit's law."""

from __future__ import annotations

import functools

import numpy as np

from jaxunilat.internal import check_choice

from ._joint import contact_time_of
from ._kelvin_voigt import restitution_and_contact_time
from ._problem import PARAMETERS
from ._uncertainty import summarize


def view(setup, z: np.ndarray, cov: np.ndarray, f: int = 0):
    """File f's z_f, the covariance of its free entries, and their indices in PARAMETERS."""
    idx = setup.layout.index[f]
    free6 = [i for i in range(len(PARAMETERS)) if idx[i] in setup.free]
    pos = [setup.free.index(idx[i]) for i in free6]
    return np.asarray(z)[idx], cov[np.ix_(pos, pos)], free6


def law_derived(setup):
    """(log κ, log k_r, mass) → (e, t_c, ∂e/∂u, ∂log t_c/∂u) for the fit's law.

    Kelvin–Voigt: the closed forms (no gravity). Hunt–Crossley: e of one impact at the
    data's typical impact speed (simulated as in `law_restitution`; gradient by central
    differences, step 1e-4 in the logs) and the undamped Hertz contact time there. A law
    without an entry in `_DERIVED` raises `ValueError` naming it.
    """
    check_choice("law", setup.law, tuple(_DERIVED))
    return _DERIVED[setup.law](setup)


def _hunt_crossley_derived(setup):
    """Hunt–Crossley's (e, t_c, ∂e/∂u, ∂log t_c/∂u) at the data's typical impact speed
    (see `law_derived`); ∂log t_c/∂log κ = −1/(n + 1) with n = 3/2."""
    speed, g = setup.speed, float(setup.datasets[0].gravity)

    def derived(lk, lr, mass):
        e, ge = _hunt_crossley_restitution(float(lk), float(lr), float(mass), speed, g)
        t_c = contact_time_of("hunt-crossley", lk, lr, mass, speed)
        return e, t_c, ge.copy(), np.array([-1.0 / 2.5, 0.0])

    return derived


#: Each law's derived quantities, by the fit's law name: the closed forms for
#: Kelvin–Voigt, simulated impacts for Hunt–Crossley.
_DERIVED = {
    "kelvin-voigt": lambda setup: restitution_and_contact_time,
    "hunt-crossley": _hunt_crossley_derived,
}

#: Central-difference step (in log κ, log k_r) of Hunt–Crossley's ∂e/∂(log κ, log k_r).
_E_STEP = 1e-4


@functools.lru_cache(maxsize=256)
def _hunt_crossley_restitution(lk: float, lr: float, mass: float, speed: float, gravity: float):
    """Hunt–Crossley's e at `speed` (m/s) and its gradient in (log κ, log k_r).

    The point and its four neighbours are one batch of simulated impacts
    (`law_restitution`'s program, rtol 1e-12). Cached: the files of a joint fit share κ,
    k_r and usually the mass, and every file's table asks for the same values.
    """
    from ._restitution import _impact_rows

    h = _E_STEP
    lks = lk + np.array([0.0, h, -h, 0.0, 0.0])
    lrs = lr + np.array([0.0, 0.0, 0.0, h, -h])
    e, _ = _impact_rows("hunt-crossley", np.exp(lks), np.exp(lrs), np.full(5, speed), mass, gravity, 1e-12)
    e = np.asarray(e, dtype=float)
    return float(e[0]), np.array([(e[1] - e[2]) / (2 * h), (e[3] - e[4]) / (2 * h)])


def derived_quantities(setup, z: np.ndarray, cov: np.ndarray, f: int = 0) -> dict:
    """The derived e and t_c entries of file f's view (see `summarize`)."""
    z6, cov6, free6 = view(setup, z, cov, f)
    mass = float(setup.datasets[f].mass)
    return summarize(z6, cov6, free6, mass, derived=law_derived(setup))[1]
