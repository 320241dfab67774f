"""What the importers share: the result object, the ball, the interval analysis, `Importer`.

An importer turns a recording (a WAV file, a phyphox export, a video-tracking table)
into an `identify.Dataset` and says what it did: which onsets it kept, which it left
out and why, what looked suspicious, and how noisy the timing is. Nothing is dropped
silently: every onset left out is a `Rejected` entry, and `ImportResult.text()` writes
them as `##` comment lines of the data file. Each importer module declares one
`Importer` (its command line and how to run it); `_registry.IMPORTERS` lists them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable

import numpy as np

from jaxunilat._internal import InputError

from ._balls import BallSpec, ball_spec
from ._format import (
    DEFAULT_GRAVITY,
    NOISE_RANGE,
    Dataset,
    _parse,
    format_dataset,
    noise_unit,
    write_text,
)

#: The restitution assumed when the release height x0 is estimated from the first interval.
ASSUMED_RESTITUTION = 0.95
#: Successive bounce intervals of a ball: the ratio I[k+1]/I[k] lies in this range
#: (restitution, drag and timing noise included); outside it an onset is misplaced.
RATIO_RANGE = (0.75, 1.1)


@dataclasses.dataclass(frozen=True)
class Rejected:
    """An onset (or a row) an importer left out.

    - `time`: s, on the recording's clock (NaN if the row had no usable time).
    - `reason`: why, in words.
    - `line`: the source line (tables) or None (audio).
    """

    time: float
    reason: str
    line: int | None = None

    def describe(self) -> str:
        """One line: where, when and why."""
        where = f"line {self.line}: " if self.line is not None else ""
        when = f"t = {self.time:.6f} s: " if math.isfinite(self.time) else ""
        return f"{where}{when}{self.reason}"


@dataclasses.dataclass(frozen=True, eq=False)
class ImportResult:
    """An imported recording: the data set and the report of how it was made.

    **Fields:**

    - `dataset`: the `identify.Dataset` (SI units; `source` names the file and importer).
    - `importer`: `"wav"`, `"phyphox"` or `"video"`.
    - `source`: the file that was read (it is never modified).
    - `accepted`: the times kept, s on the recording's clock (impacts: the onsets;
      video: the sample times before the shift to the first frame).
    - `rejected`: the onsets or rows left out, each with its reason.
    - `warnings`: suspicious but kept (an interval that breaks the decay pattern, ...).
    - `noise_estimate`: the timing-noise estimate, s (impacts), or None.
    - `noise_method`: how it was estimated, in words.
    - `notes`: facts about defaults and estimates, written as `##` comments.
    - `info`: one-line facts about the source (format, rate, columns, ...).
    - `detection`: the onset detection of a WAV import (`OnsetDetection`), else None.
    - `problems`: why the onsets are not those of one bouncing ball (`bounce_problems`),
      kept only because the import was forced; () for a plausible sequence.
    - `soundtrack`: a video clip's soundtrack imported as impacts (`import_video(...,
      soundtrack=True)`: an `ImportResult` of its own, onsets in s on the soundtrack's
      clock), else None (also where it gave none: the notes say why).
    """

    dataset: Dataset
    importer: str
    source: str
    accepted: np.ndarray
    rejected: tuple[Rejected, ...] = ()
    warnings: tuple[str, ...] = ()
    noise_estimate: float | None = None
    noise_method: str = ""
    notes: tuple[str, ...] = ()
    info: tuple[str, ...] = ()
    detection: object | None = None
    problems: tuple[str, ...] = ()
    soundtrack: ImportResult | None = None

    def summary(self) -> str:
        """The report, several lines: source, onsets kept and left out, noise, data set."""
        ds = self.dataset
        lines = [("source", f"{self.source} ({self.importer})")]
        lines += [("", text) for text in self.info]
        what = "onsets" if ds.observe == "impacts" else "samples"
        lines.append(("kept", f"{len(ds.t)} {what}"))
        lines.append(("left out", f"{len(self.rejected)}" + ("" if self.rejected else " (none)")))
        lines += [("  -", r.describe()) for r in self.rejected]
        lines += [("warning", w) for w in self.warnings]
        lines += [("NOT A BALL", f"{p} (kept because forced)") for p in self.problems]
        if self.noise_estimate is not None:
            unit, scale = ("ms", 1e3) if ds.observe == "impacts" else ("mm", 1e3)
            lines.append(("noise", f"{self.noise_estimate * scale:.4g} {unit} ({self.noise_method})"))
        elif self.noise_method:
            lines.append(("noise", self.noise_method))
        lines += [("note", n) for n in self.notes]
        meta = (
            f"scene = {ds.scene}, observe = {ds.observe}, {ds.num_rows} rows, mass = {ds.mass:g} kg, "
            f"drag = {ds.drag:g} s/m, x0 = {ds.x0:.6g} m, v0 = {ds.v0:g} m/s, "
            + ("noise = none (a fit estimates it)" if ds.noise is None else f"noise = {ds.noise:.4g}")
        )
        lines.append(("data set", meta))
        return "\n".join(f"{key:<10} {value}" if key else f"{'':<10} {value}" for key, value in lines)

    def text(self) -> str:
        """The data file: `format_dataset` with the notes and left-out onsets as `##` lines."""
        return _with_comments(format_dataset(self.dataset), self.comment_lines())

    def comment_lines(self) -> list[str]:
        """The `##` free-comment lines written before the column header."""
        out = [f"## imported by jaxunilat import {self.importer} from {os.path.basename(self.source)}"]
        out += [f"## {n}" for n in self.notes]
        if self.noise_estimate is not None and self.dataset.observe == "impacts":
            out.append(f"## timing-noise estimate: {self.noise_estimate:.3g} s ({self.noise_method})")
        out += [f"## left out: {r.describe()}" for r in self.rejected]
        out += [f"## warning: {w}" for w in self.warnings]
        out += [f"## not a bouncing ball (import forced): {p}" for p in self.problems]
        return [_one_line(line) for line in out]

    def write(self, path, *, overwrite: bool = False) -> None:
        """Write `text()` to `path` (refuses to replace a file unless `overwrite`, and
        never writes over the source)."""
        from jaxunilat._internal import check_output_paths

        name = os.fspath(path)
        check_output_paths(("path", name), inputs=(("source", self.source),))
        text = self.text()
        _parse(text, name)  # what is written reads back
        write_text(name, text, overwrite=overwrite)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _with_comments(text: str, comments: list[str]) -> str:
    """Insert `##` lines after the metadata, before the column header."""
    lines = text.split("\n")
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return "\n".join(lines[:header] + comments + lines[header:])


def _no_frames(source: str) -> bool:
    return False


@dataclasses.dataclass(frozen=True)
class Importer:
    """One importer as the command line knows it: `jaxunilat import NAME SOURCE ...`.

    Every importer takes SOURCE, `--out`, the ball (`--ball`, `--mass`, `--diameter`,
    `--drag`, `--air-density`: one `BallSpec` through `check_options`), `--x0`, `--v0`,
    `--noise`, `--plot` and `--force`; the command line adds those (with the three help
    texts below), then the importer's own flags.

    - `name`: the subcommand; `aliases`: other names for it (`import audio` is `import wav`).
    - `summary`: one line in `jaxunilat import --help`; `description`: its own `--help`.
    - `source_help`, `x0_help`, `noise_help`: the help of SOURCE, `--x0` and `--noise`.
    - `add_arguments(parser)`: adds the importer's own flags to its `argparse` parser.
    - `run(args)`: the import of `args.source` (an `ImportResult`); the flags are
      `args`' attributes (`common_keywords(args)`: those every importer takes). It raises
      `ImplausibleRecording` for what is not one ball's drop, `ValueError` for bad input.
    - `contact_sheet(source)`: whether `--plot` of this SOURCE also draws a contact sheet
      of its frames beside the figure (a video clip), so that path is checked too.
    - `observe`: what its data sets observe, "impacts" or "trace": the unit and range of
      `--noise` (`check_noise`, before SOURCE is read).
    """

    name: str
    aliases: tuple[str, ...]
    summary: str
    description: str
    source_help: str
    x0_help: str
    noise_help: str
    add_arguments: Callable
    run: Callable
    contact_sheet: Callable = _no_frames
    observe: str = "impacts"


#: The help of `--x0` of the impacts importers (`import wav`, `import phyphox`).
X0_IMPACTS = (
    "release height x0, m (default: estimated from the first interval T1 with the e of the interval ratios "
    "(0.95 where they give none) and no drag, x0 = g T1^2 / (8 e^2); the file says so in a ## comment)"
)
#: The options every importer's `run` passes on to its import function.
COMMON_OPTIONS = ("ball", "mass", "diameter", "drag", "air_density", "x0", "v0", "noise", "force")


def common_keywords(args) -> dict:
    """The options every importer takes (`COMMON_OPTIONS`), from parsed command-line `args`."""
    return {name: getattr(args, name) for name in COMMON_OPTIONS}


def check_options(*, ball, mass, diameter, drag, air_density, x0, v0, noise, observe=None) -> BallSpec:
    """Validate the metadata options (None: the default; `ValueError` names the flag) and
    return the ball's mass and drag (`ball_spec`: the ball must be stated). `noise` must be
    > 0 and, given the import's `observe` ("impacts": s; "trace", "apex": m), within the
    data format's `NOISE_RANGE` for it (`check_noise`)."""
    from jaxunilat._internal import check_range

    spec = ball_spec(ball, mass=mass, diameter=diameter, drag=drag, air_density=air_density)
    check_range("x0", x0, lo=0.0, unit="m", allow_none=True)
    check_range("v0", v0, unit="m/s", allow_none=True)
    check_range("noise", noise, lo=0.0, lo_open=True, allow_none=True)
    if observe is not None:
        check_noise(noise, observe)
    return spec


def check_noise(noise: float | None, observe: str) -> None:
    """Refuse an importer's `--noise` outside the data format's `NOISE_RANGE` for `observe`
    (impacts: s; trace, apex: m), in one line naming the flag, the value and the range,
    before the source is read (None: not given)."""
    if noise is None:
        return
    unit = noise_unit(observe)
    lo, hi = NOISE_RANGE[unit]
    if not lo <= noise <= hi:
        what = "onset-time" if unit == "s" else "position"
        raise InputError(
            f"--noise {noise:g} {unit} is out of range; valid range is [{lo:g}, {hi:g}] {unit} for an import of "
            f"observe = {observe} (the {what} standard deviation, in {'seconds' if unit == 's' else 'metres'})"
        )


def x0_from_first_interval(interval: float, *, restitution: float = ASSUMED_RESTITUTION) -> float:
    """The release height, m, that a drop from rest needs for a first bounce interval
    `interval` (s), with restitution `restitution` and no drag: the first impact speed is
    v1 = g T1 / (2 e), so x0 = v1² / (2 g) = g T1² / (8 e²)."""
    return DEFAULT_GRAVITY * interval**2 / (8.0 * restitution**2)


def source_text(path: str, importer: str, ball: str) -> str:
    """The `source` metadata: the file's base name, the importer and the ball, one line."""
    return _one_line(f"{os.path.basename(path)} (jaxunilat import {importer}, ball: {ball})")


def impacts_dataset(
    times: np.ndarray, *, source: str, importer: str, ball: BallSpec, x0, v0, noise
) -> tuple[Dataset, list[str]]:
    """An `observe = impacts` drop data set of the ball `ball`, with the importers' defaults, and the notes.

    `times` are the onsets (s, recording clock, strictly increasing, at least 2). An x0
    that is None is estimated from the first interval and written as estimated, so that
    a fit frees it. (A late export's apex, derived from a given x0, is held: freed, a fit
    whose ratio rows leave out the release lost e's interval altogether.)
    """
    times = np.asarray(times, dtype=float)
    notes = []
    if len(times) < 2:
        raise InputError(
            f"{source}: {len(times)} impact onset(s) kept; a data set of impacts needs at least 2"
        )
    estimated = ("x0",) if x0 is None else ()
    if x0 is None:
        first = float(times[1] - times[0])
        e, why = ASSUMED_RESTITUTION, "assuming"
        if len(times) >= 3:
            chain = ratio_chain(times).restitution
            if math.isfinite(chain) and RESTITUTION_RANGE[0] <= chain <= RESTITUTION_RANGE[1]:
                e, why = chain, "with the interval ratios'"
        x0 = x0_from_first_interval(first, restitution=e)
        notes.append(
            f"x0 = {x0:.6g} m estimated from the first interval {first:.6f} s {why} e = {e:.3f} and no drag "
            "(x0 = g T1^2 / (8 e^2)); measure it and pass --x0 if you can"
        )
    if v0 is None:
        v0 = 0.0
        notes.append("v0 = 0 (released from rest)")
    ds = drop_dataset(
        notes,
        observe="impacts",
        source=source,
        importer=importer,
        ball=ball,
        x0=x0,
        v0=v0,
        noise=noise,
        t=times,
        estimated=estimated,
    )
    return ds, notes


def drop_dataset(notes: list[str], *, source: str, importer: str, ball: BallSpec, **fields) -> Dataset:
    """A `scene = drop` data set of the ball `ball` (its mass and drag; where they came from
    is added to `notes`), `source` naming the file, the importer and the ball; `fields`: the
    other `Dataset` fields (observe, x0, v0, noise, t, x)."""
    notes += ball.notes
    return Dataset(
        scene="drop",
        mass=ball.mass,
        drag=ball.drag,
        source=source_text(source, importer, ball.label),
        **fields,
    )


# -- the interval sequence ----------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class IntervalFit:
    """A smooth fit to a bounce-interval sequence.

    For a constant restitution e and no drag, the interval that starts at onset t_k is
    I_k = (1 − e)(t_∞ − t_k): a straight line in t_k, whatever bounces were missed. The
    fit is a quadratic in t_k (drag bends the line), robust: intervals far from it are
    excluded and refitted.

    - `start`: the onset each interval starts at, s.
    - `interval`: the intervals, s.
    - `expected`: the fit at `start`, s.
    - `inlier`: which intervals the final fit used.
    - `scatter`: robust standard deviation of the inliers' residuals, s.
    """

    start: np.ndarray
    interval: np.ndarray
    expected: np.ndarray
    inlier: np.ndarray
    scatter: float


def fit_intervals(times: np.ndarray) -> IntervalFit | None:
    """The robust smooth fit of the intervals of `times` (s); None with fewer than 5 intervals."""
    times = np.asarray(times, dtype=float)
    start, interval = times[:-1], np.diff(times)
    n = len(interval)
    if n < 5:
        return None
    degree = 2 if n >= 7 else 1
    scale = max(float(start[-1] - start[0]), 1e-9)
    u = (start - start[0]) / scale
    inlier = np.ones(n, dtype=bool)
    expected = np.full(n, np.median(interval))
    scatter = 0.0
    for _ in range(6):
        coef = np.polyfit(u[inlier], interval[inlier], degree)
        expected = np.polyval(coef, u)
        residual = interval - expected
        mad = float(np.median(np.abs(residual[inlier] - np.median(residual[inlier]))))
        scatter = 1.4826 * mad
        # Beyond 4 robust sd and 3% of the interval: not part of the smooth decay.
        limit = np.maximum(4.0 * scatter, 0.03 * np.abs(expected))
        new = np.abs(residual) <= limit
        if new.sum() < degree + 3 or np.array_equal(new, inlier):
            break
        inlier = new
    if scatter <= 0:  # half the residuals exactly zero: use the rms instead
        dof = max(int(inlier.sum()) - (degree + 1), 1)
        scatter = float(np.sqrt(np.sum((interval - expected)[inlier] ** 2) / dof))
    return IntervalFit(start=start, interval=interval, expected=expected, inlier=inlier, scatter=scatter)


def interval_warnings(times: np.ndarray, fit: IntervalFit | None, lines=None) -> list[str]:
    """Warnings for intervals that break the smooth decay (kept, not dropped).

    `lines`: the source line of each onset, for the messages (or None).
    """
    if fit is None:
        return []
    out = []
    chain = ratio_chain(times)
    for k in np.flatnonzero((chain.spans > 1) & fit.inlier):  # a smooth fit can absorb a last one
        where = f"line {lines[k + 1]}: " if lines is not None else ""
        out.append(
            f"{where}interval {fit.interval[k]:.6f} s (onset {k + 1} -> {k + 2}, ending at t = {times[k + 1]:.6f} s) "
            f"spans {chain.spans[k]} flights of the bounce chain (e = {chain.restitution:.3f}): a missed bounce?"
        )
    for k in np.flatnonzero(~fit.inlier):
        got, exp = float(fit.interval[k]), float(fit.expected[k])
        ratio = got / exp if exp > 0 else math.inf
        if 1.6 <= ratio <= 2.4:
            why = "about twice the expected: a missed bounce?"
        elif ratio < 1:
            why = "shorter than the decay allows: an echo or a spurious onset?"
        else:
            why = "longer than the decay allows: a missed bounce or a spurious onset?"
        where = f"line {lines[k + 1]}: " if lines is not None else ""
        out.append(
            f"{where}interval {got:.6f} s (onset {k + 1} -> {k + 2}, ending at t = {times[k + 1]:.6f} s) "
            f"vs {exp:.6f} s expected from the smooth decay: {why}"
        )
    return out


def ratio_ok(r: float) -> bool:
    """Whether a successive-interval ratio I[k+1]/I[k] is one a bouncing ball can have."""
    return RATIO_RANGE[0] <= r <= RATIO_RANGE[1]


# -- the plausibility gate ------------------------------------------------------------------

#: Most bounces in a row that one interval may span (missed quiet bounces).
MAX_SPAN = 3
#: Restitutions a bouncing ball's interval ratios can show (drag-free ratio of flights).
RESTITUTION_RANGE = (0.1, 0.995)
#: A ratio whose log departs from the chain's prediction by more than this is broken.
RATIO_TOLERANCE = 0.15


class ImplausibleRecording(ValueError):
    """The onsets of an import are not those of one bouncing ball.

    - `problems`: the reasons, each one sentence.
    - `result`: the `ImportResult` that would have been returned (inspect or plot it).
    """

    def __init__(self, message: str, problems: tuple[str, ...], result=None):
        super().__init__(message)
        self.problems = problems
        self.result = result


@dataclasses.dataclass(frozen=True)
class RatioChain:
    """A bounce-interval sequence read as one bouncing ball.

    With restitution e and no drag, successive flights shrink by e; an interval that
    spans m flights (m − 1 bounces went unheard) is the first flight times
    S(m) = 1 + e + … + e^(m−1).

    - `restitution`: the closed-form e, the median ratio of successive flights (drag-free:
      drag makes it read a little low), or NaN where no ratio is below 1.
    - `spans`: flights per interval (1 normal; 2 or 3 after missed bounces).
    - `mismatch`: per successive pair, |log(observed / predicted)| of the later interval.
    - `broken`: per pair, whether the mismatch exceeds `RATIO_TOLERANCE`.
    """

    restitution: float
    spans: np.ndarray
    mismatch: np.ndarray
    broken: np.ndarray

    @property
    def missed(self) -> int:
        """The bounces inferred missing between the onsets."""
        return int(np.sum(self.spans - 1))


def _span_sum(m: int, e: float) -> float:
    return float(sum(e**j for j in range(m)))


def ratio_chain(times) -> RatioChain:
    """Read the onsets `times` (s, increasing, at least 3) as one bouncing ball (see `RatioChain`).

    Linear in the number of onsets (`chain_spans`)."""
    interval = np.diff(np.asarray(times, dtype=float))
    ratio = interval[1:] / interval[:-1]
    decaying = ratio[(ratio > 0) & (ratio < 1)]
    if len(decaying) == 0:
        nan = np.full(len(ratio), np.nan)
        return RatioChain(math.nan, np.ones(len(interval), int), nan, np.ones(len(ratio), bool))
    e = float(np.median(decaying))
    # Refine with single-flight ratios only: a missed bounce's pair of ratios is far from e.
    near = decaying[np.abs(np.log(decaying / e)) <= RATIO_TOLERANCE]
    e = float(np.median(near)) if len(near) else e
    spans, mismatch = chain_spans(interval, e)
    return RatioChain(e, spans, mismatch, mismatch > RATIO_TOLERANCE)


def chain_spans(interval: np.ndarray, e: float, *, start: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The flights each interval spans (the first: `start`) and the mismatch of each
    successive pair, for the intervals `interval` (s) of a chain with restitution `e`
    (`RatioChain`): each next span is the one of 1…`MAX_SPAN` that predicts the next
    interval best from the one before, a flight shrinking by e. Linear: the best next
    span for each span before is tabled for every pair at once (`_least_log`), then
    followed from the first interval."""
    n = len(interval)
    spans = np.ones(n, dtype=int)
    mismatch = np.zeros(max(n - 1, 0))
    if n:
        spans[0] = start
    if n < 2:
        return spans, mismatch
    sums = span_sums(e)
    predicted = np.empty((MAX_SPAN, MAX_SPAN, n - 1))  # [next span, span before, pair]
    for s in range(1, MAX_SPAN + 1):
        unit = interval[:-1] / sums[s - 1] * e ** np.int64(s)  # the next single flight
        for m in range(MAX_SPAN):
            predicted[m, s - 1] = interval[1:] / (unit * sums[m])
    choice = _least_log(predicted).tolist()
    s = start - 1
    path = [0] * (n - 1)
    for k in range(n - 1):  # a state machine of MAX_SPAN states: integers only
        s = choice[s][k]
        path[k] = s
    path_a = np.asarray(path)
    spans[1:] = path_a + 1
    previous = np.concatenate([[start - 1], path_a[:-1]])
    mismatch[:] = _abs_log(predicted[path_a, previous, np.arange(n - 1)])
    return spans, mismatch


def span_sums(e: float) -> list[float]:
    """S(m) = 1 + e + … + e^(m−1) for m = 1…`MAX_SPAN` (an interval spanning m flights
    is the first flight times S(m))."""
    return [_span_sum(m, e) for m in range(1, MAX_SPAN + 1)]


def chain_steps(before, after, span, e: float, sums: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """One step of `chain_spans` for many pairs at once: the span (1…`MAX_SPAN`) of each
    interval `after` (s) that follows `before` (s, spanning `span` flights; arrays of one
    length) in a chain with restitution `e`, and its mismatch |log(observed / predicted)|;
    `sums`: `span_sums(e)`. The same arithmetic as `chain_spans`."""
    before, after, span = np.asarray(before, dtype=float), np.asarray(after, dtype=float), np.asarray(span)
    power = np.array([0.0] + [e ** np.int64(m) for m in range(1, MAX_SPAN + 1)])
    unit = before / np.asarray([0.0, *sums])[span] * power[span]  # the next single flight
    predicted = np.stack([after / (unit * sums[m]) for m in range(MAX_SPAN)])
    best = _least_log(predicted)
    return best + 1, _abs_log(predicted[best, np.arange(len(before))])


#: Two choices whose |log| np.log puts closer than this (relative) are decided by `math.log`.
_LOG_TIE = 1e-9


def _least_log(ratio: np.ndarray) -> np.ndarray:
    """The index along axis 0 of the `ratio` (observed / predicted) whose |log| is least,
    the first of equals, as `math.log` decides: `np.log` (vectorised, fast) decides where
    the best is clear, `math.log` wherever two are within `_LOG_TIE` (the two logs may
    differ in the last bit) or a log is not finite (`math.log` raises `ValueError` on 0
    and negative values, as a chain of such intervals must)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        approx = np.abs(np.log(ratio))
        ordered = np.sort(approx, axis=0)
        close = ~(ordered[1] - ordered[0] > _LOG_TIE * ordered[1])
    best = np.argmin(approx, axis=0)
    for where in zip(*np.nonzero(close), strict=True):
        exact = [abs(math.log(ratio[(m, *where)])) for m in range(len(ratio))]
        best[where] = int(np.argmin(exact))
    return best


def _abs_log(x: np.ndarray) -> np.ndarray:
    """|log x| element by element, by `math.log` (the mismatches keep its last bit)."""
    return np.abs(np.fromiter(map(math.log, x), float, len(x)))


def bounce_problems(times) -> list[str]:
    """Why the onsets `times` (s) cannot be the impacts of one bouncing ball; [] if they can.

    A bouncing ball's flights shrink by a nearly constant ratio (its restitution, read a
    little low through drag), up to a few missed quiet bounces (an interval spanning 2 or
    3 flights). Refused: fewer than 3 onsets (nothing to check), intervals that do not
    decay, a closed-form restitution outside `RESTITUTION_RANGE`, and a ratio chain broken
    at more than one pair and more than a quarter of them (an interval off the chain's
    prediction by more than `RATIO_TOLERANCE` in log: a spurious or wrongly timed onset,
    a second drop, ringing read as bounces).
    """
    t = np.asarray(times, dtype=float)
    if len(t) < 3:
        return [f"{len(t)} onset(s): a bouncing ball needs at least 3 (two intervals) to be recognised"]
    interval = np.diff(t)
    if np.any(interval <= 0):
        return ["the onset times do not increase"]
    chain = ratio_chain(t)
    e = chain.restitution
    problems = []
    if not math.isfinite(e) or np.median(interval[1:] / interval[:-1]) >= 1.0:
        problems.append(
            f"the intervals do not decay (from {interval[0]:.4f} s to {interval[-1]:.4f} s; "
            "a bouncing ball's flights only get shorter)"
        )
        return problems
    if not RESTITUTION_RANGE[0] <= e <= RESTITUTION_RANGE[1]:
        problems.append(
            f"the interval ratios give a restitution e = {e:.3f}, outside the "
            f"{RESTITUTION_RANGE[0]:g}-{RESTITUTION_RANGE[1]:g} a bouncing ball can have"
        )
    n_broken, n_pairs = int(chain.broken.sum()), len(chain.broken)
    if n_broken > 1 and n_broken > 0.25 * n_pairs:
        where = ", ".join(f"{t[k + 1]:.4f} s" for k in np.flatnonzero(chain.broken)[:6])
        problems.append(
            f"the interval ratios do not form one bouncing ball's chain (e = {e:.3f}): {n_broken} of "
            f"{n_pairs} successive intervals are off by more than {100 * RATIO_TOLERANCE:.0f}% even "
            f"allowing up to {MAX_SPAN - 1} missed bounces in a row (at onsets {where}"
            f"{', ...' if n_broken > 6 else ''}): spurious onsets, ringing, or several drops?"
        )
    elif chain.missed > max(2, 0.3 * len(interval)):
        problems.append(
            f"{chain.missed} bounces would be missing between {len(t)} onsets: too few heard to be one ball"
        )
    return problems


#: The highest release of a drop test, m: twice the ITF tennis-ball rebound test's 2.54 m
#: (FIFA's football test drops from 2 m, FIBA's basketball test from 1.8 m, ITTF's from
#: 0.305 m), room for a release from a stand, a stairwell or a first-floor window, and for
#: the error of the drag-free estimate. A release height estimated above it
#: (`import_problems`) is no drop test; a measured `--x0` is taken as stated.
MAX_DROP_HEIGHT = 5.0


def flight_time(speed: float, drag: float, *, gravity: float = DEFAULT_GRAVITY) -> float:
    """Floor-to-floor flight time, s, of a take-off at `speed` (m/s) under gravity and
    quadratic drag `drag` (k = 1/terminal speed, s/m; 0: none).

    With ẍ = −g − g k² v|v| (`jaxunilat`'s flight model) the rise lasts atan(k u)/(g k) to
    an apex ln(1 + (k u)²)/(2 g k²); the fall from rest through it ends when
    cosh(g k τ) = exp(g k² apex) = sqrt(1 + (k u)²), so
    T(u) = (atan(k u) + asinh(k u)) / (g k), increasing in u (2u/g without drag)."""
    b = drag * speed
    if b < 1e-9:
        return 2.0 * speed / gravity
    return (math.atan(b) + math.asinh(b)) / (gravity * drag)


def longest_flight(
    drag: float, *, v0: float = 0.0, height: float = MAX_DROP_HEIGHT, gravity: float = DEFAULT_GRAVITY
) -> tuple[float, str]:
    """The longest flight between two bounces, s, of a ball with quadratic drag `drag`
    (s/m) released at `v0` (m/s) from at most `height` (m), and how it follows, in words.

    A bounce never takes off faster than the ball landed (e ≤ 1), and the ball never lands
    faster than sqrt(v0² + 2 g height) (energy: drag only takes some away) nor, with drag,
    faster than max(|v0|, 1/k) (falling, v̇ = g (1 − k² v²) draws the speed towards 1/k
    and never past it). The flight of the fastest take-off u (`flight_time`, increasing in
    u) bounds every flight; the ball's mass enters only through k. With k = 0.12 s/m (a
    40 mm table-tennis ball) it is 1.416 s, the terminal speed's limit (π/4 + asinh 1)/(g k), which a
    ball would reach only after an endless fall."""
    speed = math.sqrt(v0 * v0 + 2.0 * gravity * height)
    why = f"it lands no faster than from {height:g} m, sqrt(v0^2 + 2 g h) = {speed:.3g} m/s"
    if drag > 0 and max(abs(v0), 1.0 / drag) < speed:
        speed = max(abs(v0), 1.0 / drag)
        why = (
            f"it lands no faster than its terminal speed 1/k = {speed:.3g} m/s"
            if abs(v0) <= 1.0 / drag
            else f"it lands no faster than |v0| = {speed:.3g} m/s (above its terminal speed)"
        )
    bound = flight_time(speed, drag, gravity=gravity)
    how = (
        f"at most {bound:.4g} s with drag k = {drag:g} s/m and g = {gravity:g} m/s^2: a bounce takes off no "
        f"faster than the ball landed, {why}, and a take-off at u flies "
        + ("(atan(k u) + asinh(k u)) / (g k)" if drag > 0 else "2 u / g")
    )
    return bound, how


def import_problems(result: ImportResult, *, x0_estimated: bool) -> list[str]:
    """Why an impacts import is no drop test of one ball, beyond `bounce_problems`; [] if none.

    - The chain kept is a minority of the candidate onsets (distinct times, kept and left
      out): most of what was heard or listed is something else (clicks at random, speech,
      rows out of order), and a chain of a few of them is chance.
    - An interval longer than the ball can fly (`longest_flight` with the import's drag,
      v0 and gravity, from at most the larger of `MAX_DROP_HEIGHT` and a stated x0; an
      interval the ratio chain reads as m flights, missed bounces, may last m times that).
    - With `x0_estimated`, a release height estimated above `MAX_DROP_HEIGHT`.
    """
    ds = result.dataset
    t = np.asarray(ds.t, dtype=float)
    if ds.observe != "impacts" or len(t) < 2 or np.any(np.diff(t) <= 0):
        return []
    problems = []
    every = [float(x) for x in result.accepted] + [r.time for r in result.rejected]
    candidates = len(np.unique([x for x in every if math.isfinite(x)]))
    what = "candidate clicks" if result.importer == "wav" else "event times"
    if 2 * len(t) < candidates:
        problems.append(
            f"only {len(t)} of the {candidates} {what} are kept as the bouncing ball's: the ball's "
            "bounces would be a minority of the recording, so its chain is chance among other sounds "
            "(clicks at random, speech, rows out of order?)"
        )
    interval = np.diff(t)
    spans = ratio_chain(t).spans if len(t) >= 3 else np.ones(len(interval), dtype=int)
    height = MAX_DROP_HEIGHT if x0_estimated else max(ds.x0, MAX_DROP_HEIGHT)
    bound, how = longest_flight(ds.drag, v0=ds.v0, height=height, gravity=ds.gravity)
    over = np.flatnonzero(interval > spans * bound)
    if len(over):
        k = int(over[np.argmax(interval[over] / spans[over])])
        flights = f" ({spans[k]} flights, {spans[k] * bound:.4g} s at most)" if spans[k] > 1 else ""
        n = len(over) - 1
        more = f" (and {n} more interval{'s' if n > 1 else ''})" if n else ""
        problems.append(
            f"the interval {interval[k]:.6g} s (onset {k + 1} -> {k + 2}, ending at t = {t[k + 1]:.6g} s){flights} "
            f"is longer than any flight of this ball{more}: {how} (another sound, or times not in seconds?)"
        )
    if x0_estimated and ds.x0 > MAX_DROP_HEIGHT:
        problems.append(
            f"the first interval {interval[0]:.6g} s implies a release from x0 = {ds.x0:.4g} m "
            "(g T1^2 / (8 e^2), drag-free), "
            f"above the {MAX_DROP_HEIGHT:g} m a drop test uses at most; pass the measured --x0 if it was one"
        )
    return problems


def gate(result: ImportResult, *, force: bool, x0_estimated: bool = False, more=()) -> ImportResult:
    """Return `result` if its onsets are a drop test of one bouncing ball (`bounce_problems`,
    the importer's own `more` problems, `import_problems`: `x0_estimated` says the release
    height was estimated, not given); otherwise raise `ImplausibleRecording`, or with
    `force` return it with `problems` filled in."""
    problems = tuple(bounce_problems(result.dataset.t)) + tuple(more)
    problems += tuple(import_problems(result, x0_estimated=x0_estimated))
    if not problems:
        return result
    result = dataclasses.replace(result, problems=problems)
    if force:
        return result
    raise ImplausibleRecording(
        f"{result.source}: the onsets are not those of one bouncing ball: "
        + "; ".join(problems)
        + " (nothing written; look at it with --plot, or keep it anyway with --force)",
        problems,
        result,
    )


#: At most this many trailing onsets are left out by `trailing_breaks`.
MAX_TRAILING = 3


def trailing_breaks(times) -> list[tuple[int, str]]:
    """The trailing onsets that end the sequence off the bouncing ball's chain.

    The end of a real recording is where a ball stops bouncing freely: it is caught,
    rolls, hits an obstacle, or the recorder hears something else. Where the ratio chain
    (`ratio_chain`) breaks for the last time (an interval off its prediction by more than
    `RATIO_TOLERANCE` in log, even allowing missed bounces) within the last
    `MAX_TRAILING` onsets, the onsets after the break are not bounces of this drop.
    Returns `(index, reason)` per onset to leave out, last first, never leaving fewer
    than 4 onsets.
    """
    t = np.asarray(times, dtype=float)
    out: list[tuple[int, str]] = []
    n = len(t)
    while n >= 5:
        chain = ratio_chain(t[:n])
        broken = np.flatnonzero(chain.broken)
        if len(broken) == 0:
            break
        cut = int(broken[-1]) + 2  # the first onset whose interval broke the chain
        if cut < 4 or n - cut > MAX_TRAILING - len(out) or _broken_or_not_a_ball(t[:cut]):
            break
        e, m = chain.restitution, int(chain.spans[cut - 2])
        before = float(t[cut - 1] - t[cut - 2])
        unit = before / _span_sum(m, e) * e**m
        got = float(t[cut] - t[cut - 1])
        why = (
            f"after the last bounce of the chain (t = {t[cut - 1]:.4f} s): the interval {got:.4f} s to the "
            f"next onset breaks it, where a bounce would give {unit:.4f} s (or {unit * (1 + e):.4f} s after a "
            "missed one); the ball no longer bounced freely (caught, rolling, hit something?)"
        )
        out += [(j, why) for j in range(n - 1, cut - 1, -1)]
        n = cut
    return out


def _broken_or_not_a_ball(times) -> bool:
    """Whether `times` break their own ratio chain anywhere or are no bouncing ball."""
    return bool(ratio_chain(times).broken.any()) or bool(bounce_problems(times))
