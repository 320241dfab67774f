"""Export to MuJoCo without MuJoCo: the mapping, its uncertainty, bad inputs and the CLI.

The references are MuJoCo's documented solref/solimp formulas (written out here), the
package's Kelvin–Voigt relations (`jaxunilat.restitution`, `contact_time`) and a scipy
solution of the non-adhesive contact.
"""

import json
import math
import xml.etree.ElementTree as ET

import pytest
from jaxunilat.identify._apply._export import nonadhesive_rebound

import jaxunilat as ju
from jaxunilat import identify
from jaxunilat._cli._main import main

KAPPA, K_R, MASS = 1e4, 0.2, 2.7e-3


def fit_dict(kappa=KAPPA, k_r=K_R, mass=MASS, *, rel=0.01, rho=0.99, kappa_ok=True, e_ok=True, e_mass=None):
    """A fit JSON in `jaxunilat identify --json`'s schema, consistent with (κ, k_r, m)."""
    m_e = mass if e_mass is None else e_mass
    e = float(ju.restitution(kappa, k_r, m_e))
    t_c = float(ju.contact_time(kappa, k_r, m_e))

    def est(v, se, ok=True):
        if not ok:
            return {"value": v, "stderr": None, "ci95": None}
        return {"value": v, "stderr": se, "ci95": [v - 1.96 * se, v + 1.96 * se]}

    fit = {
        "parameters": {"kappa": est(kappa, rel * kappa, kappa_ok), "k_r": est(k_r, rel * k_r)},
        "derived": {"restitution": est(e, 1e-3, e_ok), "contact_time": est(t_c, rel * t_c, kappa_ok)},
        "identifiable": {"kappa": kappa_ok, "k_r": kappa_ok, "restitution": e_ok},
        "correlation": [[1.0, rho], [rho, 1.0]],
        "converged": True,
        "data": "data/drop_trace.csv",
        "scene": "drop",
        "observe": "trace",
    }
    if mass is not None:
        fit["mass"] = mass
    return fit


def write_fit(tmp_path, fit, name="fit.json"):
    path = tmp_path / name
    path.write_text(json.dumps(fit))
    return path


def test_direct_solref_is_mass_normalized(tmp_path):
    c = identify.mujoco_contact(write_fit(tmp_path, fit_dict()))
    assert c.mode == "direct" and c.identifiable
    assert c.solref == pytest.approx((-KAPPA / MASS, -K_R / MASS), rel=1e-15)
    lo, hi = (KAPPA - 1.96 * 0.01 * KAPPA) / MASS, (KAPPA + 1.96 * 0.01 * KAPPA) / MASS
    assert c.stiffness.ci95 == pytest.approx((lo, hi), rel=1e-12)
    assert c.stiffness.stderr == pytest.approx(0.01 * KAPPA / MASS, rel=1e-12)
    assert c.solref_ci95[0] == pytest.approx((-hi, -lo), rel=1e-12)
    assert c.attributes() == {
        "solref": f"{-KAPPA / MASS:.8g} {-K_R / MASS:.8g}",
        "solimp": "0.99 0.99 0.001 0.5 2",
        "priority": "1",
    }
    # The classic mistake (κ and k_r unnormalized) is far away.
    assert abs(c.solref[0]) > 300 * KAPPA


@pytest.mark.parametrize("d", [0.9, 0.99, 0.9999])
def test_standard_and_direct_give_mujocos_documented_stiffness_and_damping(d):
    # MuJoCo, Modeling chapter "Solver parameters" (eq:solref_direct, eq:solref_standard):
    # direct: b = damping/d_width, k = stiffness*d(r)/d_width^2;
    # standard: b = 2/(d_width*timeconst), k = d(r)/(d_width^2*timeconst^2*dampratio^2).
    fit = fit_dict(kappa=3e4, k_r=0.35, mass=4e-3)
    direct = identify.mujoco_contact(fit, impedance=d)
    standard = identify.mujoco_contact(fit, mode="standard", impedance=d)
    assert direct.solimp == standard.solimp == (d, d, 0.001, 0.5, 2.0)
    dw = d  # solimp[1]; the impedance is constant, d(r) = d
    stiffness, damping = -direct.solref[0], -direct.solref[1]
    k_direct, b_direct = stiffness * d / dw**2, damping / dw
    tc, dr = standard.solref
    k_std, b_std = d / (dw**2 * tc**2 * dr**2), 2 / (dw * tc)
    assert k_std == pytest.approx(k_direct, rel=1e-12)
    assert b_std == pytest.approx(b_direct, rel=1e-12)
    # Effective stiffness and damping d*k, d*b: kappa/m and k_r/m ...
    assert d * k_direct == pytest.approx(3e4 / 4e-3, rel=1e-12)
    assert d * b_direct == pytest.approx(0.35 / 4e-3, rel=1e-12)
    # ... so the contact's Kelvin-Voigt e and t_c are the fitted ones.
    zeta = d * b_direct / (2 * math.sqrt(d * k_direct))
    e = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    t_c = math.pi / math.sqrt(d * k_direct * (1 - zeta**2))
    assert e == pytest.approx(float(ju.restitution(3e4, 0.35, 4e-3)), rel=1e-12)
    assert t_c == pytest.approx(float(ju.contact_time(3e4, 0.35, 4e-3)), rel=1e-12)
    assert standard.dampratio.value == pytest.approx(float(ju.damping_ratio(3e4, 0.35, 4e-3)), rel=1e-12)


def test_uncertainty_carried_into_the_settings():
    fit = fit_dict()
    c = identify.mujoco_contact(fit, mode="standard")
    e_lo, e_hi = fit["derived"]["restitution"]["ci95"]
    z_lo, z_hi = c.dampratio.ci95
    # dampratio's interval is the image of e's: the ends map back onto e's ends.
    assert float(ju.restitution(1.0, 2 * z_lo, 1.0)) == pytest.approx(e_hi, rel=1e-10)
    assert float(ju.restitution(1.0, 2 * z_hi, 1.0)) == pytest.approx(e_lo, rel=1e-10)
    kr_lo, kr_hi = fit["parameters"]["k_r"]["ci95"]
    assert c.timeconst.ci95 == pytest.approx((2 * MASS / kr_hi, 2 * MASS / kr_lo), rel=1e-12)
    assert c.solref_ci95 == (c.timeconst.ci95, c.dampratio.ci95)
    assert c.restitution.ci95 == tuple(fit["derived"]["restitution"]["ci95"])
    assert c.contact_time.ci95 == tuple(fit["derived"]["contact_time"]["ci95"])
    # Delta-method stderr of timeconst = 2m/k_r.
    assert c.timeconst.stderr == pytest.approx(2 * MASS * 0.01 * K_R / K_R**2, rel=1e-12)


def test_fit_without_derived_values_uses_the_delta_method():
    fit = fit_dict()
    del fit["derived"]
    c = identify.mujoco_contact(fit)
    assert c.restitution.value == pytest.approx(float(ju.restitution(KAPPA, K_R, MASS)), rel=1e-12)
    assert c.contact_time.value == pytest.approx(float(ju.contact_time(KAPPA, K_R, MASS)), rel=1e-12)
    # t_c = pi/sqrt(kappa/m - (k_r/2m)^2): with rho = 0.99 the two relative errors nearly cancel
    # in zeta and add in t_c's kappa part; a central difference checks the delta method.
    h = 1e-6

    def tc(k, r):
        return float(ju.contact_time(k, r, MASS))

    g = ((tc(KAPPA * (1 + h), K_R) - tc(KAPPA * (1 - h), K_R)) / (2 * h * KAPPA),)
    g += ((tc(KAPPA, K_R * (1 + h)) - tc(KAPPA, K_R * (1 - h))) / (2 * h * K_R),)
    sk, sr = 0.01 * KAPPA, 0.01 * K_R
    var = (g[0] * sk) ** 2 + (g[1] * sr) ** 2 + 2 * 0.99 * g[0] * g[1] * sk * sr
    assert c.contact_time.stderr == pytest.approx(math.sqrt(var), rel=1e-5)


def test_other_mass_keeps_kappa_and_k_r(tmp_path):
    m2 = 2 * MASS
    c = identify.mujoco_contact(write_fit(tmp_path, fit_dict()), mass=m2)
    assert c.mass == m2 and c.fit_mass == MASS
    assert c.solref == pytest.approx((-KAPPA / m2, -K_R / m2), rel=1e-15)
    assert c.restitution.value == pytest.approx(float(ju.restitution(KAPPA, K_R, m2)), rel=1e-10)
    assert c.contact_time.value == pytest.approx(float(ju.contact_time(KAPPA, K_R, m2)), rel=1e-10)
    assert c.restitution.ci95[0] < c.restitution.value < c.restitution.ci95[1]
    assert any("differs from the fit's" in n for n in c.notes)
    assert "given; the fit used 0.0027 kg" in c.mjcf()


def test_mass_from_the_command_when_the_fit_has_none(tmp_path):
    path = write_fit(tmp_path, fit_dict(mass=None, e_mass=MASS))
    with pytest.raises(ValueError, match="no 'mass'.*kg"):
        identify.mujoco_contact(path)
    c = identify.mujoco_contact(path, mass=MASS)
    assert c.solref == pytest.approx((-KAPPA / MASS, -K_R / MASS), rel=1e-15) and not c.notes


def test_inconsistent_mass_is_flagged():
    c = identify.mujoco_contact(fit_dict(e_mass=4 * MASS))  # e, t_c computed with another mass
    assert any("does not match kappa, k_r" in n for n in c.notes)
    # Every number then follows kappa and k_r.
    assert c.restitution.value == pytest.approx(float(ju.restitution(KAPPA, K_R, MASS)), rel=1e-12)
    assert c.contact_time.value == pytest.approx(float(ju.contact_time(KAPPA, K_R, MASS)), rel=1e-12)


@pytest.mark.parametrize("zeta", [0.0, 0.02, 0.1, 0.3])
def test_nonadhesive_rebound_matches_scipy(zeta):
    from scipy.integrate import solve_ivp

    # Unit mass, unit omega, unit impact speed; delta = penetration. The force k*delta + c*delta'
    # (here delta + 2 zeta delta') must stay >= 0: the body leaves when it reaches zero.
    def rhs(t, y):
        return [y[1], -2 * zeta * y[1] - y[0]]

    def released(t, y):
        return y[0] + 2 * zeta * y[1]

    released.terminal, released.direction = True, -1
    sol = solve_ivp(rhs, (0, 10), [0.0, 1.0], method="DOP853", rtol=1e-13, atol=1e-15, events=released)
    t_s, (delta, rate) = sol.t_events[0][0], sol.y_events[0][0]
    if zeta == 0.0:  # no damping: released at the surface
        t_s, delta, rate = math.pi, 0.0, -1.0
    e, wt = nonadhesive_rebound(zeta)
    assert e == pytest.approx(-rate, rel=1e-9)
    assert wt == pytest.approx(t_s + delta / -rate, rel=1e-9)
    # It is more elastic than the Kelvin-Voigt law, which pulls before separation.
    assert e >= float(ju.restitution(1.0, 2 * zeta, 1.0)) - 1e-15


def test_kappa_not_identifiable_exports_e_only(tmp_path):
    fit = fit_dict(kappa_ok=False)
    for mode in ("direct", "standard"):
        c = identify.mujoco_contact(write_fit(tmp_path, fit), mode=mode)
        assert not c.identifiable
        assert c.solref is None and c.solref_ci95 is None and c.attributes() == {}
        assert c.stiffness is None and c.timeconst is None and c.contact_time is None
        assert "not identifiable" in c.notes[0]
        snippet = c.mjcf()
        assert "solref=" not in snippet and "not identifiable" in snippet
        # The e-only information: e and the damping ratio it fixes, with their intervals.
        assert c.restitution.ci95 == tuple(fit["derived"]["restitution"]["ci95"])
        assert float(ju.restitution(1.0, 2 * c.dampratio.value, 1.0)) == pytest.approx(
            fit["derived"]["restitution"]["value"], rel=1e-12
        )


def test_nothing_identifiable_is_an_error():
    with pytest.raises(ValueError, match="neither kappa nor the restitution"):
        identify.mujoco_contact(fit_dict(kappa_ok=False, e_ok=False))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(mass=0.0), r"mass = 0 kg is out of range; valid range is \(0, inf\) kg"),
        (dict(mass=-1e-3), "mass = -0.001 kg is out of range"),
        (dict(mode="soft"), "mode = 'soft' is not supported; choose one of 'direct', 'standard'"),
        (dict(impedance=1.0), r"impedance = 1 is out of range; valid range is \[0.0001, 0.9999\]"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        identify.mujoco_contact(fit_dict(), **kwargs)


def test_bad_fit_files(tmp_path):
    with pytest.raises(ValueError, match=r"fit file '.*missing.json' not found"):
        identify.mujoco_contact(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="is a directory"):
        identify.mujoco_contact(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="is not valid JSON"):
        identify.mujoco_contact(bad)
    with pytest.raises(ValueError, match="'parameters'"):
        identify.mujoco_contact({"mass": MASS})
    fit = fit_dict()
    fit["parameters"]["kappa"]["value"] = "1e4"
    with pytest.raises(ValueError, match="parameters.kappa.value = '1e4' is not a number"):
        identify.mujoco_contact(fit)
    with pytest.raises(ValueError, match="k_r = 0: the standard format cannot express"):
        identify.mujoco_contact(fit_dict(k_r=0.0), mode="standard")
    with pytest.raises(ValueError, match="not supported"):
        identify.mujoco_contact(42)


def test_fit_result_object_and_json_round_trip():
    class Result:
        def to_json_dict(self):
            return fit_dict()

    c = identify.mujoco_contact(Result(), mode="standard")
    d = json.loads(json.dumps(c.to_dict()))
    assert d["solref"] == list(c.solref) and d["attributes"] == c.attributes()
    assert d["dampratio"]["ci95"] == list(c.dampratio.ci95)


@pytest.mark.parametrize("mode", ["direct", "standard"])
def test_snippet_is_valid_xml(mode):
    c = identify.mujoco_contact(fit_dict(), mode=mode)
    snippet = c.mjcf()
    comment, attrs = snippet.rsplit("\n", 1)
    root = ET.fromstring(f"<r>{comment}<geom {attrs}/></r>")
    assert root.find("geom").attrib == c.attributes()
    assert "--" not in comment[4:-3]
    assert ("acceleration units" in comment) == (mode == "direct")
    assert "reduced mass" in comment and "priority" in comment


# -- the command line ---------------------------------------------------------------------


def _run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_export_mujoco(tmp_path, capsys):
    path = write_fit(tmp_path, fit_dict())
    code, out, err = _run(["export", "mujoco", str(path)], capsys)
    assert code == 0 and err == ""
    assert out.strip().endswith(
        f'solref="{-KAPPA / MASS:.8g} {-K_R / MASS:.8g}" solimp="0.99 0.99 0.001 0.5 2" priority="1"'
    )
    code, out, err = _run(["export", "mujoco", str(path), "--mode", "standard", "--mass", "0.0054"], capsys)
    assert code == 0
    assert f'solref="{2 * 0.0054 / K_R:.8g} {float(ju.damping_ratio(KAPPA, K_R, 0.0054)):.8g}"' in out
    assert err.startswith("jaxunilat: warning: mass 0.0054 kg differs")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--mass", "0"], "jaxunilat: error: mass = 0 kg is out of range"),
        (["--mass", "-2e-3"], "jaxunilat: error: mass = -0.002 kg is out of range"),
        (["--mode", "soft"], "jaxunilat: error: argument --mode: invalid choice"),
    ],
)
def test_cli_bad_input_exits_2(tmp_path, capsys, extra, message):
    path = write_fit(tmp_path, fit_dict())
    code, out, err = _run(["export", "mujoco", str(path), *extra], capsys)
    assert code == 2 and out == ""
    assert err.startswith(message) and err.count("\n") == 1


def test_cli_missing_file_and_unidentifiable_kappa(tmp_path, capsys):
    code, out, err = _run(["export", "mujoco", str(tmp_path / "nope.json")], capsys)
    assert code == 2 and out == "" and "nope.json' not found" in err and err.count("\n") == 1
    path = write_fit(tmp_path, fit_dict(kappa_ok=False))
    code, out, err = _run(["export", "mujoco", str(path)], capsys)
    assert code == 0 and "solref=" not in out and "dampratio" in out
    assert err.startswith("jaxunilat: warning: kappa is not identifiable")


@pytest.mark.parametrize("mode", ["direct", "standard"])
def test_match_rebound_inverts_the_nonadhesive_rebound(mode):
    fit = fit_dict(k_r=1.0)  # zeta = 0.096: the non-pulling force matters
    e, t_c = fit["derived"]["restitution"], fit["derived"]["contact_time"]
    c = identify.mujoco_contact(fit, mode=mode, match="rebound")
    assert c.match == "rebound" and any("match='rebound'" in n for n in c.notes)
    stiffness, damping = c.stiffness.value, c.damping.value
    zeta = damping / (2 * math.sqrt(stiffness))  # MuJoCo's effective damping ratio
    e_na, wt = nonadhesive_rebound(zeta)
    assert e_na == pytest.approx(e["value"], rel=1e-10)
    assert wt / math.sqrt(stiffness) == pytest.approx(t_c["value"], rel=1e-10)
    assert (c.mujoco_restitution, c.mujoco_contact_time) == (e["value"], t_c["value"])
    assert c.dampratio.value == pytest.approx(zeta, rel=1e-10)
    # dampratio's interval is the image of e's interval.
    ends = sorted(nonadhesive_rebound(z)[0] for z in c.dampratio.ci95)
    assert ends == pytest.approx(e["ci95"], rel=1e-9)
    if mode == "standard":  # timeconst = 2/damping, dampratio = zeta (documented mapping, d = d_width)
        assert c.solref == pytest.approx((2 / damping, zeta), rel=1e-12)
    else:
        assert c.solref == (-stiffness, -damping)
    # Matching the rebound needs less damping than k_r/m (the force no longer pulls).
    assert damping > 1.0 / MASS


def test_match_rebound_limits():
    # Below e = 0.2079 no non-pulling linear spring-damper rebounds (zeta -> 1/sqrt(2)).
    fit = fit_dict(kappa=1e4, k_r=5.0)
    assert float(ju.restitution(1e4, 5.0, MASS)) < 0.2
    with pytest.raises(ValueError, match="no restitution below 0.2079"):
        identify.mujoco_contact(fit, match="rebound")
    with pytest.raises(ValueError, match="match = 'force' is not supported"):
        identify.mujoco_contact(fit_dict(), match="force")


def test_cli_match_rebound(tmp_path, capsys):
    path = write_fit(tmp_path, fit_dict())
    code, out, err = _run(["export", "mujoco", str(path), "--match", "rebound"], capsys)
    c = identify.mujoco_contact(path, match="rebound")
    assert code == 0 and out.strip().endswith(" ".join(f'{k}="{v}"' for k, v in c.attributes().items()))
    assert "matched to e and t_c" in out and "match='rebound'" in err
