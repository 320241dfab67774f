"""Generate the bundled SYNTHETIC data sets of data/ (see data/README.md).

    python data/generate.py            # (re)write every file
    python data/generate.py --check    # regenerate in memory and compare; write nothing

Every file is simulated with jaxunilat's event mode (`solver="event"`, rtol = atol =
1e-12: every contact entry and exit located) from the true parameters below, then
Gaussian noise from NumPy's `default_rng` with a fixed seed is added and the values are
rounded to the stated print precision. No measured or third-party data is involved.

Besides the four data sets (jaxunilat-data files), it writes raw recordings for
`jaxunilat import`: a phone's WAV recording of a drop (`phone_drop.wav`) and phyphox
exports of drops from several heights (`phyphox_drop_*.csv`), with the faults of real
recordings (clipping, room noise, a spurious click, a missed quiet bounce, echoes and
duplicate rows) and a restitution that scatters from bounce to bounce.
"""

from __future__ import annotations

import argparse
import io
import math
import os
import re
import sys
import wave

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))  # the repository root: `identify` and `jaxunilat`

import jax  # noqa: E402
from jaxunilat.identify._data import Dataset, format_dataset, load_dataset, write_dataset  # noqa: E402

import jaxunilat  # noqa: E402

#: The seed; each file draws from its own child stream `SeedSequence(SEED).spawn(4)[i]`.
SEED = 20261122
TOL = 1e-12
GRAVITY = 9.81

#: The drop test: an ITTF-like ball (40 mm, 2.7 g) released from rest with its lowest
#: point 305 mm above a rigid surface at x = 0. The truth is given as (e, t_c); κ and k_r
#: follow from `jaxunilat.parameters_from_restitution` (inverse Kelvin–Voigt). e = 0.935
#: (with drag 0.12 s/m) gives a first rebound of about 247 mm: ITTF-compliant (240–260 mm).
DROP = dict(mass=2.7e-3, drag=0.12, x0=0.305, v0=0.0, restitution=0.935, contact_time=1.0e-3)
#: The drop trace: 1 kHz over [0, 2.5] s, noise 0.5 mm; positions printed to 1 µm.
DROP_TRACE = dict(rate=1000.0, duration=2.5, noise=0.5e-3, decimals=6)
#: The drop's impact onsets over [0, 4] s (an acoustic recording), noise 20 µs, clock
#: offset: recorded time = time since release + 0.0731 s; printed to 0.1 µs.
DROP_IMPACTS = dict(duration=4.0, noise=20e-6, offset=0.0731, decimals=7)
#: The drop's rebound apex heights over [0, 4] s, noise 1 mm, printed to 1 µm; apex
#: times rounded to 1 ms (no noise added to them).
DROP_APEX = dict(duration=4.0, noise=1.0e-3, decimals=6, time_decimals=3)
#: Two rackets 0.8 m apart (walls at ±0.4 m), the paper's ball mass and drag, and a
#: lining that is not one of the paper's: e = 0.92, t_c = 1.2 ms. 1 kHz over [0, 1.5] s.
RACKETS = dict(mass=2.37e-3, drag=0.122, gap=0.8, x0=-0.4, v0=-8.0, restitution=0.92, contact_time=1.2e-3)
RACKETS_TRACE = dict(rate=1000.0, duration=1.5, noise=0.5e-3, decimals=6)

FILES = ("drop_trace.csv", "drop_impacts.csv", "drop_apex.csv", "rackets_trace.csv")
SOURCE = (
    "SYNTHETIC: data/generate.py, jaxunilat event mode (rtol=atol=1e-12), seed {seed}; see data/README.md"
)


def true_parameters(spec: dict) -> tuple[float, float]:
    """(κ [N/m], k_r [N·s/m]) of a scene's stated (e, t_c) and mass."""
    kappa, k_r = jaxunilat.parameters_from_restitution(
        spec["restitution"], spec["contact_time"], spec["mass"]
    )
    return float(kappa), float(k_r)


def _ball(spec: dict) -> jaxunilat.Ball:
    kappa, k_r = true_parameters(spec)
    if "gap" in spec:
        lower, upper = -spec["gap"] / 2, spec["gap"] / 2
    else:
        lower, upper = 0.0, None
    return jaxunilat.Ball(
        kappa=kappa, k_r=k_r, mass=spec["mass"], gravity=GRAVITY, drag=spec["drag"], lower=lower, upper=upper
    )


def _grid(rate: float, duration: float) -> np.ndarray:
    n = round(duration * rate)
    return np.round(np.arange(n + 1) / rate, 9)


def _simulate(spec: dict, ts: np.ndarray):
    return jaxunilat.simulate(
        _ball(spec),
        [spec["x0"], spec["v0"]],
        float(ts[-1]),
        solver="event",
        rtol=TOL,
        atol=TOL,
        ts=ts,
        outputs=("x",),
    )


#: The most bounces one run may hold (a static size for the jitted event extraction).
MAX_BOUNCES = 64


@jax.jit
def _observe(events):
    return jaxunilat.impact_times(events, MAX_BOUNCES), jaxunilat.apexes(events, MAX_BOUNCES)


def _events(sol) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(impact onset times, rebound apex times, rebound apex heights) of a drop run."""
    if int(sol.events.count) >= 4 * MAX_BOUNCES:
        raise RuntimeError(f"more than {MAX_BOUNCES} bounces: raise MAX_BOUNCES")
    impacts, (t_apex, h_apex) = _observe(sol.events)
    impacts = np.asarray(impacts)[np.isfinite(impacts)]
    t_apex, h_apex = np.asarray(t_apex), np.asarray(h_apex)
    rebound = np.isfinite(t_apex) & (t_apex > impacts[0])  # not the release itself
    return impacts, t_apex[rebound], h_apex[rebound]


def generate() -> dict[str, Dataset]:
    """The four data sets, in memory."""
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(SEED).spawn(4)]
    source = SOURCE.format(seed=SEED)
    common = dict(scene="drop", mass=DROP["mass"], drag=DROP["drag"], x0=DROP["x0"], v0=DROP["v0"])
    out = {}

    # One drop run covers the trace (first 2.5 s of samples), the impacts and the apexes.
    ts = _grid(DROP_TRACE["rate"], max(DROP_TRACE["duration"], DROP_IMPACTS["duration"]))
    sol = _simulate(DROP, ts)
    x = np.asarray(sol["x"])
    keep = ts <= DROP_TRACE["duration"] + 1e-12
    noisy = x[keep] + DROP_TRACE["noise"] * rngs[0].standard_normal(int(keep.sum()))
    out["drop_trace.csv"] = Dataset(
        observe="trace",
        **common,
        noise=DROP_TRACE["noise"],
        t=ts[keep],
        x=np.round(noisy, DROP_TRACE["decimals"]),
        source=source,
    )
    impacts, t_apex, h_apex = _events(sol)
    impacts = impacts[impacts <= DROP_IMPACTS["duration"]]
    recorded = (
        impacts + DROP_IMPACTS["offset"] + DROP_IMPACTS["noise"] * rngs[1].standard_normal(len(impacts))
    )
    out["drop_impacts.csv"] = Dataset(
        observe="impacts",
        **common,
        noise=DROP_IMPACTS["noise"],
        t=np.round(recorded, DROP_IMPACTS["decimals"]),
        source=source,
    )
    heights = h_apex + DROP_APEX["noise"] * rngs[2].standard_normal(len(h_apex))
    out["drop_apex.csv"] = Dataset(
        observe="apex",
        **common,
        noise=DROP_APEX["noise"],
        t=np.round(t_apex, DROP_APEX["time_decimals"]),
        h=np.round(heights, DROP_APEX["decimals"]),
        source=source,
    )

    ts = _grid(RACKETS_TRACE["rate"], RACKETS_TRACE["duration"])
    x = np.asarray(_simulate(RACKETS, ts)["x"])
    noisy = x + RACKETS_TRACE["noise"] * rngs[3].standard_normal(len(ts))
    out["rackets_trace.csv"] = Dataset(
        scene="rackets",
        observe="trace",
        mass=RACKETS["mass"],
        drag=RACKETS["drag"],
        x0=RACKETS["x0"],
        v0=RACKETS["v0"],
        gap=RACKETS["gap"],
        noise=RACKETS_TRACE["noise"],
        t=ts,
        x=np.round(noisy, RACKETS_TRACE["decimals"]),
        source=source,
    )
    return out


# -- raw recordings for `jaxunilat import` ------------------------------------------------

#: The ball of the raw recordings: a 40 mm, 2.7 g ball on a hard floor, with quadratic
#: drag 0.12 s/m. Its mean restitution e = 0.955 and contact time t_c = 0.7 ms give κ and
#: k_r (Kelvin–Voigt); every bounce i draws its own e_i = e (1 + 0.003 N(0, 1)) (spin,
#: contact point and seam make a real ball's restitution scatter by 0.2–0.5%).
BOUNCING = dict(mass=2.7e-3, drag=0.12, restitution=0.955, contact_time=0.7e-3, scatter=0.003)
#: Child seeds (SeedSequence(SEED).spawn(...)) of the raw recordings: the phone drop's e
#: scatter, its room noise, then one per phyphox export; 0–3 are the data sets above.
RAW_SEEDS = dict(phone_bounces=4, phone_noise=5, phyphox=(6, 7, 8, 9, 10))

#: `phone_drop.wav`: 48 kHz, 16-bit PCM, mono, 7.0 s. The ball is released from rest with
#: its lowest point 250 mm above the floor at t = 0.55 s on the recording's clock.
#: Click i (a damped two-mode resonance, 3.3 and 5.2 kHz, rising in 40 µs, decaying in
#: 0.9 ms, with two room reflections at 2.9 and 6.3 ms) starts at the impact onset with
#: amplitude 2.4 (v_i / v_1)² full scale: the first ones clip. Room noise: pink noise
#: (0.0015 rms) plus white noise (0.0005 rms) plus 50 Hz hum (0.006) and its third
#: harmonic (0.002). Bounce 24 is rendered at 0.3% of its amplitude (a quiet bounce no
#: detector can hear: missed), and a handling click (1.7 kHz, 0.08 full scale) sounds
#: 70 ms after bounce 6, where no bounce can be (spurious).
PHONE = dict(
    file="phone_drop.wav",
    x0=0.25,
    offset=0.55,
    rate=48000,
    duration=7.0,
    first_amplitude=2.4,
    modes=((3300.0, 1.0, 0.0), (5200.0, 0.6, 0.7)),
    rise=40e-6,
    decay=0.9e-3,
    reflections=((2.9e-3, 0.3), (6.3e-3, 0.15)),
    pink=0.0015,
    white=0.0005,
    hum=((50.0, 0.006), (150.0, 0.002)),
    missed=24,
    missed_gain=0.003,
    spurious_after=6,
    spurious_delay=0.070,
    spurious=dict(frequency=1700.0, amplitude=0.08, decay=0.6e-3),
)

#: The phyphox exports: the same ball dropped from rest from several heights (lowest
#: point above the floor), each recording with its own clock (the release is at `offset`
#: on it). The app times each impact to the audio sample (48 kHz): the recorded time is
#: the onset + offset + N(0, (21 µs)²), rounded to the sample grid, printed to 1 µs.
#: `bounces` regular rows are written, from bounce `late_start` + 1 (the 12 cm export
#: starts at bounce 2: the app was started late); the 22 cm export hears a stray onset (a
#: handling click) `stray_fraction` of the way from bounce `stray_after` to the next one;
#: the 30 cm export then misses a quiet bounce, hears one more, an echo 130 ms later and
#: the echo's duplicate. Rows are written as phyphox writes them (`phyphox_text`).
PHYPHOX = (
    dict(file="phyphox_drop_10cm.csv", x0=0.10, offset=1.8734, bounces=14, sep=",", decimal=".", quote=True),
    dict(file="phyphox_drop_15cm.csv", x0=0.15, offset=0.9412, bounces=14, sep=";", decimal=",", quote=True),
    dict(
        file="phyphox_drop_22cm.csv",
        x0=0.22,
        offset=2.4567,
        bounces=15,
        sep="\t",
        decimal=".",
        quote=False,
        stray=dict(after=4, fraction=0.4),
    ),
    dict(
        file="phyphox_drop_30cm.csv",
        x0=0.30,
        offset=1.2345,
        bounces=15,
        sep=",",
        decimal=".",
        quote=True,
        faulty_ending=dict(echo_delay=0.130),
    ),
    dict(
        file="phyphox_drop_12cm.csv",
        x0=0.12,
        offset=0.7321,
        bounces=13,
        sep=",",
        decimal=".",
        quote=True,
        late_start=1,
    ),
)
PHYPHOX_TIMING = dict(rate=48000, noise=21e-6, decimals=6)
PHYPHOX_HEADER = ("Event time (s)", "Interval (s)")


def bouncing_parameters(restitution: float) -> tuple[float, float]:
    """(κ [N/m], k_r [N·s/m]) of the raw recordings' ball for one bounce's restitution."""
    return true_parameters(dict(BOUNCING, restitution=restitution))


@jax.jit
def _first_bounce(events):
    return jaxunilat.impact_times(events, 1)[0], jaxunilat.apexes(events, 3)


def bounces(x0: float, until: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A drop from rest at height `x0` (m), bounce by bounce, until an onset passes `until` (s).

    Each bounce is its own event-mode run, from one apex (the release first) to the
    next, with its own κ_i, k_r_i from e_i = e (1 + scatter N(0, 1)).

    **Returns:** `onset` (s since the release), `speed` (impact speed, m/s), `restitution` (e_i).
    """
    g = GRAVITY
    t_apex, h_apex = 0.0, x0
    onset, speed, e_i = [], [], []
    while True:
        e = BOUNCING["restitution"] * (1.0 + BOUNCING["scatter"] * rng.standard_normal())
        kappa, k_r = bouncing_parameters(e)
        ball = jaxunilat.Ball(
            kappa=kappa,
            k_r=k_r,
            mass=BOUNCING["mass"],
            gravity=g,
            drag=BOUNCING["drag"],
            lower=0.0,
            upper=None,
        )
        span = 2.5 * math.sqrt(2.0 * h_apex / g) + 5e-3  # to past the next apex
        sol = jaxunilat.simulate(
            ball,
            [h_apex, 0.0],
            (t_apex, t_apex + span),
            solver="event",
            rtol=TOL,
            atol=TOL,
            samples=2,
            outputs=("x",),
        )
        hit, (ta, ha) = _first_bounce(sol.events)
        hit, ta, ha = float(hit), np.asarray(ta), np.asarray(ha)
        after = np.flatnonzero(np.isfinite(ta) & (ta > hit))
        if not math.isfinite(hit) or not after.size:
            raise RuntimeError(f"bounce {len(onset) + 1}: no impact and rebound apex within {span:.3f} s")
        if hit > until:
            break
        if len(onset) >= 400:
            raise RuntimeError(f"more than 400 bounces before t = {until} s: the ball comes to rest first")
        onset.append(hit)
        speed.append(-float(jaxunilat.contact_table(sol, ball)["v_in"][0]))
        e_i.append(e)
        t_apex, h_apex = float(ta[after[0]]), float(ha[after[0]])
    return dict(onset=np.asarray(onset), speed=np.asarray(speed), restitution=np.asarray(e_i))


def _raw_rngs() -> dict:
    children = np.random.SeedSequence(SEED).spawn(1 + max(RAW_SEEDS["phyphox"]))
    rng = lambda i: np.random.default_rng(children[i])  # noqa: E731
    return dict(
        phone_bounces=rng(RAW_SEEDS["phone_bounces"]),
        phone_noise=rng(RAW_SEEDS["phone_noise"]),
        phyphox=[rng(i) for i in RAW_SEEDS["phyphox"]],
    )


def phone_truth(rngs: dict | None = None) -> dict:
    """The truth of `phone_drop.wav`, on the recording's clock.

    **Returns:** `onset` (s: every impact onset in the recording, the click starts),
    `speed` (m/s), `restitution` (e_i), `rendered` (False for the missed quiet bounce),
    `spurious` (s: the start of the handling click).
    """
    rngs = rngs or _raw_rngs()
    p = PHONE
    run = bounces(p["x0"], p["duration"] - p["offset"] - 0.05, rngs["phone_bounces"])
    onset = run["onset"] + p["offset"]
    rendered = np.ones(len(onset), dtype=bool)
    rendered[p["missed"] - 1] = False
    spurious = float(onset[p["spurious_after"] - 1] + p["spurious_delay"])
    return dict(
        onset=onset, speed=run["speed"], restitution=run["restitution"], rendered=rendered, spurious=spurious
    )


def _click(s: np.ndarray, modes, rise: float, decay: float) -> np.ndarray:
    """A click that starts at s = 0 (s: time since its start, s): damped modes (frequency
    Hz, weight, phase) under a rise 1 − exp(−s/rise) and a decay exp(−s/decay)."""
    s = np.maximum(s, 0.0)
    shape = (1.0 - np.exp(-s / rise)) * np.exp(-s / decay)
    return shape * sum(w * np.sin(2 * np.pi * f * s + phi) for f, w, phi in modes)


def render_phone(truth: dict, rng: np.random.Generator) -> np.ndarray:
    """The samples of `phone_drop.wav` (int16) for `truth` (see `PHONE`)."""
    p = PHONE
    rate = p["rate"]
    n = int(round(p["duration"] * rate))
    t = np.arange(n) / rate
    x = np.zeros(n)
    span = int(0.03 * rate)

    def add(start: float, amplitude: float, modes, decay: float, reflections) -> None:
        i0 = int(math.floor(start * rate)) + 1  # the first sample after the click starts
        idx = np.arange(i0, min(i0 + span, n))
        s = t[idx] - start
        wave = _click(s, modes, p["rise"], decay)
        for delay, gain in reflections:
            wave += gain * _click(s - delay, modes, p["rise"], decay) * (s >= delay)
        x[idx] += amplitude * wave

    v1 = truth["speed"][0]
    for onset, v, shown in zip(truth["onset"], truth["speed"], truth["rendered"], strict=True):
        gain = 1.0 if shown else p["missed_gain"]
        add(onset, gain * p["first_amplitude"] * (v / v1) ** 2, p["modes"], p["decay"], p["reflections"])
    sp = p["spurious"]
    add(truth["spurious"], sp["amplitude"], ((sp["frequency"], 1.0, 0.0),), sp["decay"], ())
    # Room noise: pink (1/f power, above 20 Hz) + white + hum.
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / rate)
    spectrum *= np.where(f > 20.0, 1.0 / np.sqrt(np.maximum(f, 20.0) / 20.0), 0.0)
    pink = np.fft.irfft(spectrum, n)
    x += p["pink"] * pink / np.std(pink) + p["white"] * rng.standard_normal(n)
    for freq, amp in p["hum"]:
        x += amp * np.sin(2 * np.pi * freq * t + rng.uniform(0, 2 * np.pi))
    return np.clip(np.round(x * 32768.0), -32768, 32767).astype(np.int16)


def _wav_bytes(samples: np.ndarray, rate: int) -> bytes:
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(samples.astype("<i2").tobytes())
    return buf.getvalue()


def phyphox_throws(rngs: dict | None = None) -> list[dict]:
    """The phyphox exports' truth and rows, one dict per export (in `PHYPHOX` order).

    **Returns** per export: `onset` (s, recording clock: every true onset from bounce 1
    up to the last row), `recorded` (s: the times written, row by row), `kind` (per row:
    "bounce", "stray", "echo" or "duplicate"), `bounce` (per row: the true onset's index,
    -1 for stray/echo/duplicate rows), `missed` (indices of true onsets with no row,
    those before a late start included).
    """
    rngs = rngs or _raw_rngs()
    out = []
    for spec, rng in zip(PHYPHOX, rngs["phyphox"], strict=True):
        late = spec.get("late_start", 0)
        total = late + spec["bounces"] + (2 if "faulty_ending" in spec else 0)
        fall = math.sqrt(2 * spec["x0"] / GRAVITY)
        # Simulate far enough for `total` onsets (the intervals shrink by about e each bounce).
        horizon = fall + 2 * fall * BOUNCING["restitution"] * total
        run = bounces(spec["x0"], horizon, rng)
        onset = run["onset"][:total] + spec["offset"]
        if len(onset) < total:
            raise RuntimeError(f"{spec['file']}: {len(onset)} onsets simulated, {total} needed")
        timing = PHYPHOX_TIMING
        heard = onset + timing["noise"] * rng.standard_normal(total)
        heard = np.round(heard * timing["rate"]) / timing["rate"]
        last = late + spec["bounces"]
        rows, kind = list(heard[late:last]), ["bounce"] * spec["bounces"]
        index, missed = list(range(late, last)), list(range(late))
        if "stray" in spec:  # a handling click between two bounces, on the sample grid
            k = spec["stray"]["after"]  # bounce number (1-based): row k - late - 1 is it
            at = heard[k - 1] + spec["stray"]["fraction"] * (heard[k] - heard[k - 1])
            rows.insert(k - late, np.round(at * timing["rate"]) / timing["rate"])
            kind.insert(k - late, "stray")
            index.insert(k - late, -1)
        if "faulty_ending" in spec:
            missed.append(last)  # too quiet: no row
            rows.append(heard[last + 1])
            kind.append("bounce")
            index.append(last + 1)
            echo = (
                np.round((rows[-1] + spec["faulty_ending"]["echo_delay"]) * timing["rate"]) / timing["rate"]
            )
            rows += [echo, echo]
            kind += ["echo", "duplicate"]
            index += [-1, -1]
        out.append(
            dict(
                spec=spec,
                onset=onset,
                restitution=run["restitution"][:total],
                recorded=np.round(np.asarray(rows), timing["decimals"]),
                kind=kind,
                bounce=np.asarray(index),
                missed=np.asarray(missed, dtype=int),
            )
        )
    return out


def phyphox_text(throw: dict) -> str:
    """The export file of one throw as phyphox's "Acoustic Stopwatch" writes it: a header
    row, then per row the event time t(k) and the interval to the NEXT event,
    t(k+1) − t(k) (the difference of the printed times), 0 on the last row; in the
    throw's separator and decimal mark."""
    spec = throw["spec"]
    sep, dec = spec["sep"], spec["decimal"]
    header = [f'"{h}"' if spec["quote"] else h for h in PHYPHOX_HEADER]
    digits = PHYPHOX_TIMING["decimals"]
    times = throw["recorded"]
    lines = [sep.join(header)]
    for i, t in enumerate(times):
        cells = [f"{t:.{digits}f}", f"{(times[i + 1] - t) if i + 1 < len(times) else 0.0:.{digits}f}"]
        lines.append(sep.join(c.replace(".", dec) for c in cells))
    return "\r\n".join(lines) + "\r\n"


def generate_raw() -> tuple[dict[str, bytes], dict]:
    """The raw recordings (file name -> bytes: the WAV and the phyphox exports) and their
    truth: `phone_truth`'s, with the phyphox exports' (`phyphox_throws`) under "throws"."""
    rngs = _raw_rngs()
    truth = phone_truth(rngs)
    out = {PHONE["file"]: _wav_bytes(render_phone(truth, rngs["phone_noise"]), PHONE["rate"])}
    truth["throws"] = phyphox_throws(rngs)
    for throw in truth["throws"]:
        out[throw["spec"]["file"]] = phyphox_text(throw).encode("utf-8")
    return out, truth


def phone_truth_table(truth: dict) -> str:
    """The README table of `phone_drop.wav`'s true onsets (markdown)."""
    rows = [
        "| bounce | onset (s, recording clock) | impact speed (m/s) | e_i | in the recording |",
        "|---|---|---|---|---|",
    ]
    for i, (t, v, e, shown) in enumerate(
        zip(truth["onset"], truth["speed"], truth["restitution"], truth["rendered"], strict=True)
    ):
        what = "click" if shown else "MISSED (rendered below the noise)"
        rows.append(f"| {i + 1} | {t:.6f} | {v:.4f} | {e:.5f} | {what} |")
    after = PHONE["spurious_after"]
    rows.append(
        f"| - | {truth['spurious']:.6f} | - | - | SPURIOUS handling click ({PHONE['spurious_delay'] * 1e3:g} ms after bounce {after}) |"
    )
    return "\n".join(rows)


def phyphox_truth_lines(throws: list[dict]) -> list[str]:
    """The README lines of the phyphox exports' true onsets."""
    return [f"- `{th['spec']['file']}`: " + ", ".join(f"{t:.6f}" for t in th["onset"]) for th in throws]


def _table_rows(text: str) -> list[list[str]]:
    return [
        [c.strip() for c in line.strip("|").split("|")]
        for line in text.splitlines()
        if re.match(r"\| (\d+|-) \|", line)
    ]


def _close(a: str, b: str, tol: float) -> bool:
    if a == b:
        return True
    try:
        return abs(float(a) - float(b)) <= tol
    except ValueError:
        return False


def _check_raw(fresh: dict[str, bytes], truth: dict, directory: str) -> list[str]:
    """Compare regenerated raw recordings with the files: identical bytes, or (a rounding
    flip from ~1e-12 solver differences between machines) the WAV samples within 1 LSB
    and every phyphox number within one unit of its last printed digit; and the README's
    truth table of the WAV within the same precision."""
    problems = []
    specs = {spec["file"]: spec for spec in PHYPHOX}
    for name, data in fresh.items():
        path = os.path.join(directory, name)
        if not os.path.isfile(path):
            problems.append(f"{name}: missing")
            continue
        with open(path, "rb") as f:
            stored = f.read()
        if stored == data:
            continue
        if name.endswith(".wav"):
            a, b = (np.frombuffer(x[44:], dtype="<i2").astype(int) for x in (stored, data))
            if stored[:44] != data[:44] or len(a) != len(b) or np.max(np.abs(a - b)) > 1:
                problems.append(f"{name}: the header differs or samples differ by more than 1 LSB")
            continue
        spec = specs[name]
        sa, sb = (x.decode("utf-8").split("\r\n") for x in (stored, data))
        bad = len(sa) != len(sb) or sa[0] != sb[0]
        for la, lb in zip(sa[1:], sb[1:], strict=False) if not bad else ():
            fa = [c.replace(spec["decimal"], ".") for c in la.split(spec["sep"])]
            fb = [c.replace(spec["decimal"], ".") for c in lb.split(spec["sep"])]
            tol = 1.01 * 10.0 ** -PHYPHOX_TIMING["decimals"]
            if len(fa) != len(fb) or not all(_close(x, y, tol) for x, y in zip(fa, fb, strict=True)):
                bad = True
        if bad:
            problems.append(f"{name}: rows differ beyond the last printed digit")
    with open(os.path.join(directory, "README.md"), encoding="utf-8") as f:
        readme = f.read()
    stated = _table_rows(readme)
    table = _table_rows(phone_truth_table(truth))
    if len(stated) != len(table) or not all(
        len(r) == len(s)
        and all(_close(x, y, 1.01e-6) for x, y in zip(r[:2], s[:2], strict=True))
        and r[4] == s[4]
        for r, s in zip(table, stated, strict=False)
    ):
        problems.append("README.md: the phone_drop.wav truth table differs from the regenerated one")
    for line in phyphox_truth_lines(truth["throws"]):
        head, numbers = line.split(": ", 1)
        stated = next((x for x in readme.splitlines() if x.startswith(head + ": ")), None)
        values = stated.split(": ", 1)[1].split(", ") if stated else []
        expect = numbers.split(", ")
        if len(values) != len(expect) or not all(
            _close(a, b, 1.01e-6) for a, b in zip(values, expect, strict=True)
        ):
            problems.append(f"README.md: the true onsets of {head[2:]} differ from the regenerated ones")
    return problems


def _resolution(name: str, column: str) -> float:
    if name == "drop_impacts.csv":
        return 10.0 ** -DROP_IMPACTS["decimals"]
    if name == "drop_apex.csv" and column == "t":
        return 10.0 ** -DROP_APEX["time_decimals"]
    return 1e-6


def check(datasets: dict[str, Dataset], directory: str = HERE) -> list[str]:
    """Compare regenerated data sets with the files; return the problems (empty: reproduced).

    Text identical is "bit-for-bit"; otherwise every metadata value and column must be
    equal and every number within one unit of its last printed digit (a rounding flip
    from ~1e-12 solver differences between machines).
    """
    problems = []
    for name, fresh in datasets.items():
        path = os.path.join(directory, name)
        if not os.path.isfile(path):
            problems.append(f"{name}: missing")
            continue
        with open(path, encoding="utf-8") as f:
            if f.read() == format_dataset(fresh):
                continue
        stored = load_dataset(path)
        for key in ("scene", "observe", "mass", "drag", "x0", "v0", "gap", "noise", "gravity", "source"):
            if getattr(stored, key) != getattr(fresh, key):
                problems.append(
                    f"{name}: {key} = {getattr(stored, key)!r}, regenerated {getattr(fresh, key)!r}"
                )
        if stored.columns != fresh.columns or stored.num_rows != fresh.num_rows:
            problems.append(f"{name}: columns/rows {stored.columns}x{stored.num_rows} != regenerated")
            continue
        for column in fresh.columns:
            diff = np.max(np.abs(getattr(stored, column) - getattr(fresh, column)))
            if not diff <= 1.01 * _resolution(name, column):
                problems.append(f"{name}: column {column} differs by up to {diff:.3g}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--check", action="store_true", help="regenerate in memory and compare with the files; write nothing"
    )
    args = parser.parse_args(argv)
    datasets = generate()
    raw, truth = generate_raw()
    if args.check:
        problems = check(datasets) + _check_raw(raw, truth, HERE)
        for p in problems:
            print(f"MISMATCH {p}")
        print("data/: " + ("all files reproduced" if not problems else f"{len(problems)} mismatches"))
        return 1 if problems else 0
    for name, ds in datasets.items():
        path = os.path.join(HERE, name)
        write_dataset(path, ds, overwrite=True)
        print(f"wrote {path}: {ds.observe}, {ds.num_rows} rows, {os.path.getsize(path)} bytes")
    for name, data in raw.items():
        path = os.path.join(HERE, name)
        with open(path, "wb") as f:
            f.write(data)
        print(f"wrote {path}: {len(data)} bytes")
    for label, spec in (("drop", DROP), ("rackets", RACKETS), ("raw recordings", BOUNCING)):
        kappa, k_r = true_parameters(spec)
        print(
            f"{label}: e = {spec['restitution']}, t_c = {spec['contact_time']} s -> kappa = {kappa!r} N/m, k_r = {k_r!r} N*s/m"
        )
    print("phone_drop.wav truth (data/README.md):")
    print(phone_truth_table(truth))
    return 0


if __name__ == "__main__":
    sys.exit(main())
