"""Exported settings, run in MuJoCo: a drop test against jaxunilat's event mode.

A sphere falls onto a plane in MuJoCo with the geom attributes that `jaxunilat export
mujoco` prints (the plane keeps MuJoCo's default contact parameters), integrated with
RK4 at dt = t_c/200. The same drop in jaxunilat's event mode (the exact Kelvin–Voigt
model with located contacts, tolerance 1e-12) is the reference: e within 3e-3 and t_c
within 2%, for two parameter sets and both solref formats. MuJoCo's own rebound is also
checked against the non-adhesive closed form, and the classic mistake (κ and k_r
passed unnormalized) against the same tolerance, to show the test can fail.
`match="rebound"` (settings that make MuJoCo's non-pulling contact reproduce e and t_c)
is checked the same way, including a strongly damped contact.
"""

import json

import numpy as np
import pytest

mujoco = pytest.importorskip(
    "mujoco", reason="MuJoCo is not installed; install the extra: pip install '.[mujoco]'"
)

import jaxunilat as ju  # noqa: E402
from jaxunilat import identify  # noqa: E402

#: (κ N/m, k_r N·s/m, m kg): a table-tennis ball (Table 1 example 2's κ, k_r at 2.7 g), a
#: heavier, stiffer ball, and a strongly damped contact (ζ = 0.096, e = 0.74) where
#: MuJoCo's non-pulling force matters.
SETS = {"ttball": (1e4, 0.2, 2.7e-3), "heavy": (2e5, 2.0, 0.025), "damped": (1e4, 1.0, 2.7e-3)}
RADIUS = 0.02  # m
H0, V0 = 1e-3, 2.5  # start 1 mm above the plane at 2.5 m/s down: the end of a 0.32 m drop


def _fit_json(path, kappa, k_r, mass):
    e, t_c = float(ju.restitution(kappa, k_r, mass)), float(ju.contact_time(kappa, k_r, mass))
    fit = {
        "parameters": {
            "kappa": {"value": kappa, "stderr": 0.01 * kappa, "ci95": [0.98 * kappa, 1.02 * kappa]},
            "k_r": {"value": k_r, "stderr": 0.01 * k_r, "ci95": [0.98 * k_r, 1.02 * k_r]},
        },
        "derived": {
            "restitution": {"value": e, "stderr": 1e-3, "ci95": [e - 2e-3, e + 2e-3]},
            "contact_time": {"value": t_c, "stderr": 0.01 * t_c, "ci95": [0.98 * t_c, 1.02 * t_c]},
        },
        "identifiable": {"kappa": True, "k_r": True, "restitution": True},
        "correlation": [[1.0, 0.9], [0.9, 1.0]],
        "converged": True,
        "mass": mass,
        "data": "synthetic",
        "scene": "drop",
        "observe": "trace",
    }
    path.write_text(json.dumps(fit))
    return path


@pytest.fixture(scope="module")
def jaxunilat_drops():
    """jaxunilat's event-mode rebound (e, t_c) for each parameter set: the reference."""
    out = {}
    for name, (kappa, k_r, mass) in SETS.items():
        ball = ju.Ball(kappa=kappa, k_r=k_r, mass=mass, drag=None, lower=0.0, upper=None)
        t1 = H0 / V0 + 1.5 * float(ju.contact_time(kappa, k_r, mass))
        sol = ju.simulate(ball, [H0, -V0], t1, solver="event", rtol=1e-12, atol=1e-12)
        table = ju.contact_table(sol, ball)
        assert len(table["t_in"]) == 1 and np.isfinite(table["t_out"][0])
        out[name] = (float(table["restitution"][0]), float(table["t_out"][0] - table["t_in"][0]))
    return out


def mujoco_drop(attributes: str, mass: float, dt: float, t1: float) -> tuple[float, float]:
    """Drop a free sphere with `attributes` onto a default plane; return MuJoCo's (e, t_c).

    The contact's start and end are where the sphere's distance to the plane crosses
    zero, interpolated linearly between steps (as the contact table locates them).
    """
    xml = f"""
    <mujoco>
      <option timestep="{dt!r}" integrator="RK4"/>
      <worldbody>
        <geom name="floor" type="plane" size="1 1 0.1"/>
        <body name="ball" pos="0 0 {RADIUS + H0!r}">
          <freejoint/>
          <geom type="sphere" size="{RADIUS}" mass="{mass!r}" {attributes}/>
        </body>
      </worldbody>
    </mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qvel[2] = -V0
    n = int(np.ceil(t1 / dt))
    z, v = np.empty(n + 1), np.empty(n + 1)
    z[0], v[0] = data.qpos[2] - RADIUS, data.qvel[2]
    for i in range(1, n + 1):  # a few hundred steps of MuJoCo's own C loop
        mujoco.mj_step(model, data)
        z[i], v[i] = data.qpos[2] - RADIUS, data.qvel[2]
    t = dt * np.arange(n + 1)
    below = z < 0
    (into,) = np.flatnonzero(~below[:-1] & below[1:])[:1]
    (out,) = np.flatnonzero(below[:-1] & ~below[1:])[:1]

    def cross(i):
        f = z[i] / (z[i] - z[i + 1])
        return t[i] + f * dt, v[i] + f * (v[i + 1] - v[i])

    (t_in, v_in), (t_out, v_out) = cross(into), cross(out)
    return -v_out / v_in, t_out - t_in


@pytest.mark.parametrize("mode", ["direct", "standard"])
@pytest.mark.parametrize(
    ("name", "match"), [("ttball", "law"), ("heavy", "law"), ("ttball", "rebound"), ("damped", "rebound")]
)
def test_mujoco_drop_matches_jaxunilat(tmp_path, jaxunilat_drops, name, match, mode):
    kappa, k_r, mass = SETS[name]
    fit = _fit_json(tmp_path / "fit.json", kappa, k_r, mass)
    contact = identify.mujoco_contact(fit, mode=mode, match=match)
    attributes = contact.mjcf().splitlines()[-1]  # the printed attribute line, as a user pastes it
    assert attributes.startswith('solref="')
    t_c = contact.contact_time.value
    e_mj, tc_mj = mujoco_drop(attributes, mass, dt=t_c / 200, t1=H0 / V0 + 1.5 * t_c)
    e_ref, tc_ref = jaxunilat_drops[name]
    assert abs(e_mj - e_ref) <= 3e-3, (e_mj, e_ref)
    assert abs(tc_mj / tc_ref - 1) <= 0.02, (tc_mj, tc_ref)
    # MuJoCo's contact cannot pull: its rebound is the non-adhesive law's (gravity is
    # nearly cancelled in a MuJoCo contact, and its effect is below 5e-4 here).
    assert abs(e_mj - contact.mujoco_restitution) <= 1e-3, (e_mj, contact.mujoco_restitution)
    assert abs(tc_mj / contact.mujoco_contact_time - 1) <= 1e-3


def test_unnormalized_solref_fails_the_same_check(jaxunilat_drops):
    """The classic mistake, solref = (−κ, −k_r), is caught by the tolerances above."""
    kappa, k_r, mass = SETS["ttball"]
    t_c = float(ju.contact_time(kappa, k_r, mass))
    wrong = f'solref="{-kappa!r} {-k_r!r}" solimp="0.99 0.99 0.001 0.5 2" priority="1"'
    e_mj, tc_mj = mujoco_drop(wrong, mass, dt=t_c / 200, t1=H0 / V0 + 30 * t_c)
    e_ref, tc_ref = jaxunilat_drops["ttball"]
    assert e_mj - e_ref > 3e-2 and tc_mj / tc_ref > 10  # e ≈ 0.997, t_c ≈ 31 ms


def test_damped_contact_shows_the_non_pulling_force(tmp_path, jaxunilat_drops):
    """At ζ = 0.096 the fitted force law (match='law') rebounds 1.5e-2 more elastically in
    MuJoCo, exactly as the non-adhesive closed form predicts: a real model difference
    that match='rebound' (tested above) compensates."""
    kappa, k_r, mass = SETS["damped"]
    contact = identify.mujoco_contact(_fit_json(tmp_path / "fit.json", kappa, k_r, mass))
    t_c = contact.contact_time.value
    e_mj, _ = mujoco_drop(contact.mjcf().splitlines()[-1], mass, dt=t_c / 200, t1=H0 / V0 + 1.5 * t_c)
    e_ref, _ = jaxunilat_drops["damped"]
    assert e_mj - e_ref > 1e-2
    assert abs(e_mj - contact.mujoco_restitution) <= 1e-3
