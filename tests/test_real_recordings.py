"""Real recordings of real balls, end to end: `jaxunilat import` with its defaults, then
`jaxunilat identify`, on public lab and course data that nobody here made.

The recordings are not part of the project (no licence to redistribute most of them):
they are read from `../shared/real-recordings/` beside the checkout, and every test here
is skipped, saying so, where that folder is absent (a user's own clone).

What the ball must give (the reference e of each recording, from a fit made
independently of this project with scipy: constant restitution, quadratic drag,
instant impacts) is written below with its source. The contract: every recording
imports with default settings (only its metadata given: release height, and the ball: a
`--ball` preset or its mass and drag),
and `identify` either reports an e within ±0.02 of the reference (the blue ball's
throws vary: 0.80-0.93), or exits 3 saying why. Never exit 0 with a number the data
contradict.
"""

import json
import os
import re

import numpy as np
import pytest

from jaxunilat._cli._main import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.normpath(os.path.join(ROOT, os.pardir, "shared", "real-recordings"))

pytestmark = pytest.mark.skipif(
    not os.path.isdir(REAL),
    reason=f"real recordings not found at {REAL} (they are not shipped with the project): skipped",
)

#: Per item: the files, the metadata given to the importer, and the accepted e band.
#: The balls: the ping-pong and tennis balls by their presets (`--ball`: 2.7 g, k = 0.116 s/m;
#: 57.7 g, k = 0.0454 s/m); the others' masses and drags as the recordings' sources state them
#: (drag k = 1/terminal speed).
ITEMS = {
    "pingpong": dict(
        files=["eeps_pingpong.wav"], kind="wav", args=["--ball", "pingpong"], band=(0.9268, 0.9668)
    ),
    "basketball": dict(
        files=["mth337_basketball.wav"],
        kind="wav",
        args=["--mass", "0.6", "--drag", "0.047"],
        band=(0.838, 0.878),
    ),
    "rubberball": dict(
        files=["mth337_rubberball.wav"],
        kind="wav",
        args=["--mass", "0.05", "--drag", "0.04"],
        band=(0.889, 0.929),
    ),
    "blue": dict(
        folder="giiulia_blue_ball",
        kind="phyphox",
        args=["--mass", "0.04", "--drag", "0.04"],
        band=(0.80, 0.93),
    ),
    "tennis": dict(
        folder="giiulia_tennis_ball",
        kind="phyphox",
        args=["--ball", "tennis"],
        band=(0.740, 0.794),
    ),
    "golf": dict(
        folder="giiulia_golf_ball",
        kind="phyphox",
        args=["--mass", "0.0415", "--drag", "0.029"],
        band=(0.871, 0.921),
    ),
}
#: Exports that start at the second bounce (the recordings' source says so): their e may
#: also be off, as long as the import or the fit says so.
LATE = {"drop080cm_CR_method2.csv", "drop090cm_CR_method2.csv"}


def _cases():
    for item, spec in ITEMS.items():
        folder = os.path.join(REAL, spec.get("folder", ""))
        names = spec.get("files") or (sorted(os.listdir(folder)) if os.path.isdir(folder) else [])
        for name in names:
            yield pytest.param(item, os.path.join(folder, name), id=f"{item}-{name}")


def _height(path: str) -> list[str]:
    """The release height from a file name such as drop065cm_..., as --x0 (m)."""
    found = re.search(r"drop(\d+)cm", os.path.basename(path))
    return ["--x0", f"{int(found.group(1)) / 100:g}"] if found else []


def _run(argv, capsys):
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.slow
@pytest.mark.parametrize("item, path", list(_cases()))
def test_a_real_recording_gives_the_reference_e_or_exit_3(item, path, tmp_path, capsys):
    spec = ITEMS[item]
    data, fit_json = tmp_path / "data.csv", tmp_path / "fit.json"
    argv = ["import", spec["kind"], path, "--out", str(data), *spec["args"], *_height(path)]
    code, out, err = _run(argv, capsys)
    assert code == 0, f"the import with default settings failed:\n{out}\n{err}"
    # One start (the default is 3): the same answers on these recordings at a third of the cost;
    # the closed-form gate, not the number of starts, is what stands between a wrong basin and
    # exit 0. `test_the_default_fit_of_a_throw` runs the command line's defaults.
    argv = ["--no-cache", "identify", str(data), "--json", str(fit_json), "--starts", "1"]
    code, out, err = _run(argv, capsys)
    fit = json.loads(fit_json.read_text())
    e = fit["derived"]["restitution"]["value"]
    lo, hi = spec["band"]
    if code == 3:  # a refusal must say why
        assert "exit status 3" in out and ("rejected:" in out or "did not converge" in out), out
        assert not any(fit["identifiable"].values())
        if os.path.basename(path) not in LATE:
            pytest.xfail(f"identify exits 3 on this recording (allowed, but noted): e = {e:.4f}")
        return
    assert code == 0, f"{out}\n{err}"
    assert lo <= e <= hi, f"e = {e:.4f} outside {lo}-{hi}, exit 0:\n{out}"
    # Onset timing of ~1 ms (a phone, a lab microphone, phyphox) cannot resolve a contact of
    # about a millisecond: κ and t_c are never the data's (the recordings' README says so).
    assert not fit["identifiable"]["kappa"] and not fit["identifiable"]["contact_time"], out
    ci = fit["derived"]["restitution"]["ci95"]
    assert ci[0] < e < ci[1] and 1e-4 < (ci[1] - ci[0]) / 2 < 0.1, f"the 95% CI of e {ci} is not honest"


def test_eeps_onsets_match_the_authors_bounce_times(capsys, tmp_path):
    """The importer's onsets against the recording author's own bounce times (peaks of the
    sound, a few ms after each onset): within 5 ms after one constant shift, none extra
    among the author's span, none missing."""
    author = np.loadtxt(
        os.path.join(REAL, "eeps_pingpong_author_bounce_times.csv"), delimiter=",", skiprows=1, usecols=0
    )
    author = np.asarray(author) * 1e-3
    from jaxunilat import identify

    onsets = np.asarray(
        identify.import_wav(os.path.join(REAL, "eeps_pingpong.wav"), ball="pingpong").dataset.t
    )
    inside = onsets[(onsets > author[0] - 0.05) & (onsets < author[-1] + 0.02)]
    assert len(inside) == len(author), (inside, author)
    shift = float(np.median(author - inside))
    assert 0.0 <= shift < 0.005  # peaks come after onsets
    assert np.max(np.abs(author - inside - shift)) < 5e-3


def test_a_late_export_is_noticed(capsys, tmp_path):
    """The golf exports that start at the second bounce: the import says so (and moves x0 to
    the apex before the first recorded bounce), so the fit's e is the ball's."""
    for name in sorted(LATE):
        path = os.path.join(REAL, "giiulia_golf_ball", name)
        argv = [
            "import",
            "phyphox",
            path,
            "--out",
            str(tmp_path / "d.csv"),
            *ITEMS["golf"]["args"],
            *_height(path),
        ]
        code, out, _ = _run(argv, capsys)
        assert code == 0 and "late start" in out, out
        (tmp_path / "d.csv").unlink()


def test_the_default_fit_of_a_throw(tmp_path, capsys):
    """`jaxunilat import` and `jaxunilat identify` with every default (3 starts), one throw."""
    path = os.path.join(REAL, "giiulia_tennis_ball", "drop65cm_throw01.csv")
    data = tmp_path / "throw.csv"
    argv = ["import", "phyphox", path, "--out", str(data), *ITEMS["tennis"]["args"], *_height(path)]
    assert _run(argv, capsys)[0] == 0
    code, out, _ = _run(["--no-cache", "identify", str(data), "--json", str(tmp_path / "f.json")], capsys)
    e = json.loads((tmp_path / "f.json").read_text())["derived"]["restitution"]
    assert code == 0 and ITEMS["tennis"]["band"][0] <= e["value"] <= ITEMS["tennis"]["band"][1], out
