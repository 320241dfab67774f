"""The ball is stated, never assumed.

A data file's mass scales κ and its drag bends every flight, and neither can be read from
the onsets: `jaxunilat import` refuses to guess them (exit 2, one line naming the presets
and the flags), `--ball NAME` takes them from a ball's rules (mass, diameter) and the drag
of a sphere, and `jaxunilat identify --mass/--drag` replaces a file's values and says so.

The references here are computed in the test from the governing bodies' numbers and the
drag of a sphere, ½ ρ C_d A v² = m g k² v² (k = 1/terminal speed), not taken from the code.
"""

import json
import math
import os

import numpy as np
import pytest
from synthetic_audio import background, click, write_wav

from jaxunilat import identify
from jaxunilat._cli._main import main

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
RHO, G = 1.204, 9.81  # air at 20 C and sea level, kg/m^3; gravity, m/s^2
#: Every preset's name, as `--ball` takes it.
PRESETS = (
    "pingpong",
    "tennis",
    "golf",
    "squash",
    "racquetball",
    "basketball",
    "baseball",
    "lacrosse",
    "glass-marble",
    "steel",
)


def _k(mass, diameter, cd):
    """k = sqrt(rho C_d A / (2 m g)), s/m."""
    return math.sqrt(RHO * cd * math.pi * diameter**2 / 4 / (2 * mass * G))


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _header(path) -> dict:
    """The `# key = value` metadata of a data file."""
    out = {}
    for line in open(path, encoding="utf-8"):
        if line.startswith("# ") and " = " in line:
            key, value = line[2:].split(" = ", 1)
            out[key.strip()] = value.strip()
    return out


# -- the presets -----------------------------------------------------------------------------


def test_the_presets_and_their_drag():
    assert tuple(identify.BALLS) == PRESETS
    ping, tennis = identify.ball_spec("pingpong"), identify.ball_spec("tennis")
    # ITTF: 40 mm, 2.7 g; a smooth sphere, C_d = 0.47: about the 0.12 s/m used so far.
    assert ping.mass == 2.7e-3 and identify.BALLS["pingpong"].diameter == 0.040
    assert ping.drag == pytest.approx(_k(2.7e-3, 0.040, 0.47), rel=5e-3)
    assert ping.drag == pytest.approx(0.12, rel=0.05)
    # ITF: 56.0-59.4 g, 6.54-6.86 cm, mid values; felt, C_d = 0.55: the 0.046 s/m of the
    # real-recordings README.
    assert tennis.mass == pytest.approx((56.0 + 59.4) / 2e3)
    assert identify.BALLS["tennis"].diameter == pytest.approx((6.54 + 6.86) / 200)
    assert tennis.drag == pytest.approx(_k(0.0577, 0.067, 0.55), rel=5e-3)
    assert tennis.drag == pytest.approx(0.046, rel=0.03)
    # Within the rules' limits: golf (USGA/R&A), basketball (FIBA size 7, circumference).
    golf, basket = identify.BALLS["golf"], identify.BALLS["basketball"]
    assert golf.mass <= 45.93e-3 and golf.diameter >= 42.67e-3
    assert 0.567 <= basket.mass <= 0.650 and 0.749 <= math.pi * basket.diameter <= 0.780
    assert identify.ball_spec("basketball").drag == pytest.approx(0.047, rel=0.02)
    for name in PRESETS:
        assert identify.BALLS[name].reference, name


def test_a_steel_ball_needs_its_diameter_and_overrides_are_noted():
    with pytest.raises(ValueError, match=r"diameter=M"):
        identify.ball_spec("steel")
    steel = identify.ball_spec("steel", diameter=0.02)
    assert steel.mass == pytest.approx(7850 * math.pi * 0.02**3 / 6, rel=1e-3)
    assert steel.drag == pytest.approx(_k(steel.mass, 0.02, 0.47), rel=5e-3)
    heavier = identify.ball_spec("tennis", mass=0.06)
    assert heavier.mass == 0.06 and heavier.drag == pytest.approx(_k(0.06, 0.067, 0.55), rel=5e-3)
    assert any("0.06 kg as stated" in n and "0.0577" in n for n in heavier.notes)
    assert identify.ball_spec("tennis", drag=0.05).drag == 0.05
    stated = identify.ball_spec(mass=0.05, drag=0.04)
    assert (stated.mass, stated.drag, stated.ball) == (0.05, 0.04, None)


def test_the_python_importers_refuse_an_unstated_ball(tmp_path):
    with pytest.raises(ValueError, match=r"the ball is not stated: give ball='pingpong'\|'tennis'"):
        identify.import_wav(os.path.join(DATA, "phone_drop.wav"))
    with pytest.raises(ValueError, match="the ball is not stated"):
        identify.import_phyphox(os.path.join(DATA, "phyphox_drop_30cm.csv"), mass=2.7e-3)
    with pytest.raises(ValueError, match="the ball is not stated"):
        identify.import_video(os.path.join(DATA, "drop_trace.csv"), scale=1.0)


# -- the command line ------------------------------------------------------------------------

SOURCES = {
    "wav": ["phone_drop.wav"],
    "phyphox": ["phyphox_drop_30cm.csv"],
    "video": ["drop_trace.csv", "--scale", "1"],
}


@pytest.mark.parametrize("kind", list(SOURCES))
@pytest.mark.parametrize(
    "given", [[], ["--mass", "0.0027"], ["--drag", "0.12"]], ids=["none", "mass", "drag"]
)
def test_import_without_a_ball_exits_2_with_one_line(tmp_path, capsys, kind, given):
    name, *more = SOURCES[kind]
    out = tmp_path / "out.csv"
    code, stdout, err = _run(["import", kind, os.path.join(DATA, name), "--out", out, *more, *given], capsys)
    assert code == 2 and stdout == "" and not out.exists()
    (line,) = err.strip().splitlines()
    assert f"import {kind}: " in line and "the ball is not stated" in line, line
    assert "--ball " + "|".join(PRESETS) in line, line
    assert "--mass KG with --diameter M (or --drag S_PER_M)" in line, line


def test_import_steel_needs_a_diameter(tmp_path, capsys):
    src = os.path.join(DATA, "phone_drop.wav")
    code, _, err = _run(["import", "wav", src, "--ball", "steel", "--out", tmp_path / "s.csv"], capsys)
    assert code == 2 and "--ball steel has no standard size: give --diameter M" in err
    code, _, err = _run(
        ["import", "wav", src, "--ball", "steel", "--diameter", "20", "--out", tmp_path / "s"], capsys
    )
    assert code == 2 and "millimetres written as metres?" in err


def _tennis_onsets(x0=1.0, e=0.75, k=0.046, start=0.6):
    """Impact onsets (s) of a tennis ball dropped from rest at x0 (m): restitution e, quadratic
    drag k (s/m), closed-form flights (fall from an apex h: speed sqrt(1 - exp(-2 g k^2 h)) / k;
    a take-off at u: apex ln(1 + (k u)^2) / (2 g k^2), flight (atan(k u) + asinh(k u)) / (g k))."""
    g = G
    t = start + math.acosh(math.exp(g * k * k * x0)) / (g * k)
    onsets, h = [t], x0
    while True:
        u = e * math.sqrt(-math.expm1(-2 * g * k * k * h)) / k
        flight = (math.atan(k * u) + math.asinh(k * u)) / (g * k)
        if flight < 0.06:
            return np.asarray(onsets)
        t += flight
        onsets.append(t)
        h = math.log1p((k * u) ** 2) / (2 * g * k * k)


def test_a_tennis_ball_wav_imports_with_the_tennis_ball(tmp_path, capsys):
    rate, rng = 44100, np.random.default_rng(7)
    onsets = _tennis_onsets()
    n = int((onsets[-1] + 0.5) * rate)
    x = background(rng, n, rate, 1e-3)
    for t0, interval in zip(onsets, np.diff(np.append(onsets, onsets[-1] + 0.06)), strict=True):
        first = int(math.floor(t0 * rate)) + 1
        s = np.arange(first, min(n, first + int(0.25 * rate))) / rate - t0
        x[first : first + len(s)] += click(rng, s, rate, 0.6 * (interval / 0.7) ** 1.5)
    src, out = tmp_path / "tennis.wav", tmp_path / "tennis.csv"
    write_wav(src, x, rate)
    code, stdout, err = _run(["import", "wav", src, "--ball", "tennis", "--out", out], capsys)
    assert code == 0, stdout + err
    head = _header(out)
    assert float(head["mass"]) == pytest.approx(0.0577)
    assert float(head["drag"]) == pytest.approx(_k(0.0577, 0.067, 0.55), rel=5e-3)
    assert head["source"] == "tennis.wav (jaxunilat import wav, ball: tennis)"
    text = out.read_text()
    assert "## ball: tennis" in text and "ITF Rules of Tennis" in text and "## drag = 0.0454 s/m" in text
    ds = identify.load_dataset(out)
    assert len(ds.t) >= len(onsets) - 2 and np.min(np.abs(ds.t[0] - onsets)) < 1e-3


# -- identify --mass, --drag -----------------------------------------------------------------


def test_identify_mass_and_drag_overrides_are_reported(tmp_path, capsys):
    path = os.path.join(DATA, "drop_impacts.csv")  # mass 2.7 g, drag 0.12 s/m
    plain, heavy = tmp_path / "plain.json", tmp_path / "heavy.json"
    code, out, _ = _run(["--no-cache", "identify", path, "--starts", "1", "--json", plain], capsys)
    assert code == 0 and "overridden" not in out
    code, out, _ = _run(
        ["--no-cache", "identify", path, "--starts", "1", "--json", heavy, "--mass", "0.0054"], capsys
    )
    assert code == 0, out
    assert "mass               = 0.0054 kg" in out  # [[Data]]
    assert "mass overridden: 0.0054 kg (file: 0.0027 kg)" in out  # [[Notes]]
    a, b = json.loads(plain.read_text()), json.loads(heavy.read_text())
    assert b["mass"] == 0.0054 and b["overrides"] == {"mass": {"value": 0.0054, "files": [0.0027]}}
    assert "mass overridden: 0.0054 kg (file: 0.0027 kg)" in b["notes"] and a["overrides"] == {}
    # The motion fixes kappa/m and k_r/m: twice the mass, twice kappa, the same e.
    kappa = b["parameters"]["kappa"]["value"] / a["parameters"]["kappa"]["value"]
    assert kappa == pytest.approx(2.0, rel=0.01)
    assert b["derived"]["restitution"]["value"] == pytest.approx(
        a["derived"]["restitution"]["value"], abs=1e-4
    )
    code, out, _ = _run(
        ["--no-cache", "identify", path, "--starts", "1", "--json", heavy, "--drag", "0.1"], capsys
    )
    assert "drag overridden: 0.1 s/m (file: 0.12 s/m)" in out
    assert json.loads(heavy.read_text())["overrides"]["drag"] == {"value": 0.1, "files": [0.12]}
    code, _, err = _run(["identify", path, "--mass", "0"], capsys)
    assert code == 2 and "--mass = 0 kg is out of range" in err
