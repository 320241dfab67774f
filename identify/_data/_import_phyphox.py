"""Impact onsets from a phyphox export: "Acoustic Stopwatch" or "(In)elastic collision".

`import_phyphox` reads the table (`_table_read.read_table`: CSV or `.xlsx`), finds the
onset times (event times, cumulated intervals, or a one-row export's columns), leaves out
duplicates, stray onsets between two bounces and the events after the ball stopped
bouncing freely, and writes an impacts data set; `PHYPHOX` is its command line.

The stray search (`_leave_out_strays`) is bounded: a short export's candidates are each
tried on the chain re-read, a long one's on the chain with its restitution held
(`_LocalChain`, linear in the onsets); a sequence that cannot decay whatever few onsets
are left out is searched for none (`_never_decays`), and the gate refuses it.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from jaxunilat._internal import InputError

from ._format import DEFAULT_GRAVITY
from ._import import (
    RATIO_TOLERANCE,
    X0_IMPACTS,
    Importer,
    ImportResult,
    Rejected,
    chain_steps,
    check_options,
    common_keywords,
    fit_intervals,
    gate,
    impacts_dataset,
    interval_warnings,
    ratio_chain,
    span_sums,
    trailing_breaks,
)
from ._table_read import (
    Table,
    find_column,
    junk_rows,
    noise_note,
    read_table,
    seconds_per_unit,
    table_result,
)

#: The interval column's two conventions: "next" is phyphox's own export ("Acoustic
#: Stopwatch", sheet or CSV "All": row k holds t(k+1) − t(k), 0 on the last row);
#: "previous" holds t(k) − t(k−1), empty (or 0) on the first row.
CONVENTIONS = {
    "next": "the interval to the NEXT event, t(k+1) - t(k), 0 on the last row (phyphox's own export)",
    "previous": "the interval since the PREVIOUS event, t(k) - t(k-1), empty or 0 on the first row",
}
#: At most this many stray onsets are left out of one export.
MAX_STRAYS = 3
#: Up to this many onsets, each candidate stray is tried on the chain re-read without it
#: (`_best_stray`); beyond, with the chain's restitution held (`_LocalChain`), linear in
#: the onsets. Every real export is far shorter (a drop test heard for 10 s: 30-80 onsets).
EXACT_STRAYS = 500
#: Beyond `EXACT_STRAYS`, at most this many of the best candidates are re-read (each re-read
#: is linear in the onsets): where none of them passes, none is left out.
MAX_REREAD = 10
#: At most this many bounces are looked for before the first recorded one (a late start).
MAX_LATE = 6


def import_phyphox(
    path,
    *,
    ball: str | None = None,
    mass: float | None = None,
    diameter: float | None = None,
    drag: float | None = None,
    air_density: float | None = None,
    x0: float | None = None,
    v0: float | None = None,
    noise: float | None = None,
    force: bool = False,
) -> ImportResult:
    """Impact onsets from a phyphox "Acoustic Stopwatch" or "(In)elastic collision" export.

    Reads CSV (comma, semicolon or tab separated; decimal point or comma; detected) or
    `.xlsx` (with `openpyxl`). Onset times (s) come from the event-time column (`Event
    time`, `Time`, `t`) if there is one, else by cumulating the interval column
    (`Interval`, `Difference`, `dt`; the first event at t = 0); the one-row exports with
    `Start`/`Stop k` or `Bounce k` columns are read too.

    **The interval column.** phyphox writes on row k the interval to the NEXT event,
    t(k+1) − t(k), with 0 on the last row; other tools write the interval since the
    previous event. Which one a file uses is decided from the data (the intervals against
    the event times' differences, shifted both ways; with intervals only, from the empty
    first row or the 0 on the last row) and stated in the notes; a row whose interval
    disagrees with the event times under that convention is a warning.

    Rows with a repeated event time (a duplicate trigger) or an earlier one, rows without
    a time, and junk rows after the data are left out and reported. A stray onset between
    two bounces is left out, with its reason, when without it the interval ratios form
    one bouncing ball's chain again (`identify.ratio_chain`) while they do not with it.
    Nothing else is dropped: an interval that breaks the smooth decay (an echo, a missed
    bounce) is kept and reported as a warning, for a robust fit to deal with.

    **A late start.** With `x0` given (and v0 = 0), the first interval T1 must be the
    flight after a drop from x0; if it fits the flight after bounce n + 1 better (the
    export starts n bounces late), the data set's x0 becomes the apex before the first
    recorded bounce, the apex of a quadratic-drag flight model with the ball's drag (x0·e^(2n)
    with the ratio chain's e where the drag is 0), and a warning and a note say so with
    the given value.

    **Arguments:** as `import_wav` (`noise` default: none, so a fit estimates σ from its
    residuals; x0 default: estimated from the first interval with the interval ratios'
    e and no drag); `force`: return the result even when the onsets are not those of a bouncing
    ball (`bounce_problems`, kept in `problems`) instead of raising `ImplausibleRecording`.

    **Returns:** an `ImportResult`.
    """
    spec = check_options(
        ball=ball, mass=mass, diameter=diameter, drag=drag, air_density=air_density, x0=x0, v0=v0, noise=noise
    )
    table = read_table(path)
    name = os.fspath(path)
    notes: list[str] = []
    rejected: list[Rejected] = junk_rows(table)
    warnings: list[str] = []
    times, lines = _phyphox_events(table, notes, warnings, rejected)
    times, lines = _leave_out_strays(times, lines, rejected)
    ends = trailing_breaks(times)  # last first
    rejected += [Rejected(times[j], reason, lines[j]) for j, reason in reversed(ends)]
    for j, _ in ends:
        del times[j], lines[j]
    times_a = np.asarray(times, dtype=float)
    fit = fit_intervals(times_a)
    warnings += interval_warnings(times_a, fit, lines)
    estimate = method = None
    if fit is not None:
        estimate = fit.scatter / math.sqrt(2.0)
        method = "robust scatter of the intervals about a smooth fit, /sqrt(2); not written as noise"
    if x0 is not None and not v0:
        x0 = _late_start(times_a, x0, spec.drag, notes, warnings)
    ds, more = impacts_dataset(times_a, source=name, importer="phyphox", ball=spec, x0=x0, v0=v0, noise=noise)
    notes += more
    noise_note(noise, notes)
    result = table_result(
        table,
        ds,
        importer="phyphox",
        source=name,
        accepted=times_a,
        rejected=sorted(rejected, key=lambda r: r.line or 0),
        notes=notes,
        warnings=warnings,
        noise_estimate=estimate,
        noise_method=method or "",
    )
    return gate(result, force=force, x0_estimated=x0 is None)


def _phyphox_events(
    table: Table, notes: list[str], warnings: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """The onset times (s) and their lines, from whichever columns the export has."""
    cols = table.columns
    time_i = find_column(cols, (r"event\s*time", r"time", r"t", r"timestamp", r".*time.*"))
    interval_i = find_column(cols, (r"interval", r"difference", r"dt", r"delta\s*t", r"Δt", r".*interval.*"))
    wide = [i for i, c in enumerate(cols) if re.fullmatch(r"start|stop(\s*\d+)?|bounce\s*\d+", c.name, re.I)]
    if time_i is None and len(wide) >= 2:
        return _one_row_events(table, wide, notes, warnings, rejected)
    if time_i is not None:
        return _timed_events(table, time_i, interval_i, notes, warnings, rejected)
    if interval_i is not None:
        return _cumulated_events(table, interval_i, notes, rejected)
    raise InputError(
        f"{table.at(table.header_line)}: no event-time or interval column among "
        f'{", ".join(repr(c.header) for c in cols)}; expected e.g. "Event time (s)" or "Interval (s)"'
    )


def _one_row_events(
    table: Table, wide: list[int], notes: list[str], warnings: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """Onset times (s) from a one-row export's `Start`/`Stop k` or `Bounce k` columns."""
    cols = table.columns
    times: list[float] = []
    lines: list[int] = []
    scale = seconds_per_unit(table, cols[wide[0]], notes)
    (line, values), *others = table.rows
    if others:
        warnings.append(f"{len(others)} more rows after {table.unit} {line} are not read (one-row export)")
    for k, i in enumerate(wide):
        v = values[i]
        if v is None or (k > 0 and v <= 0):
            rejected.append(Rejected(math.nan, f"column {cols[i].header!r}: no event (not triggered)", line))
            continue
        if times and v * scale <= times[-1]:
            rejected.append(
                Rejected(v * scale, f"column {cols[i].header!r}: not after the previous event", line)
            )
            continue
        times.append(v * scale)
        lines.append(line)
    notes.append(
        "one-row export: events read from the " + ", ".join(cols[i].header for i in wide) + " columns "
        "(the app's heights and energies, which assume no drag, are not read)"
    )
    return times, lines


def _agree(interval: float, difference: float) -> bool:
    """Whether an interval cell (s) equals a difference of event times (s) to print precision."""
    return abs(interval - difference) <= max(2e-6, 1e-4 * abs(interval))


def _timed_convention(rows: list[tuple[int, float | None, float | None]]) -> tuple[str | None, str, bool]:
    """Which convention the interval column of `rows` ((line, t s, interval s)) follows.

    **Returns** (convention: "next", "previous" or None where the column is empty; the
    note saying how it was decided; whether the column agrees with the times at all).
    """
    ts = [t for _, t, _ in rows]
    ds = [d for _, _, d in rows]
    if all(d is None for d in ds):
        return None, "the interval column is empty: onset times from the event times only", True
    pairs = [k for k in range(len(rows) - 1) if ts[k] is not None and ts[k + 1] is not None]
    nxt = sum(ds[k] is not None and _agree(ds[k], ts[k + 1] - ts[k]) for k in pairs)
    prev = sum(ds[k + 1] is not None and _agree(ds[k + 1], ts[k + 1] - ts[k]) for k in pairs)
    how = (
        f"it equals the next row's event time minus this row's on {nxt} of {len(pairs)} rows and this row's "
        f"minus the previous row's on {prev}"
    )
    if nxt != prev:
        convention, assumed = ("next" if nxt > prev else "previous"), ""
    else:
        first_empty = ds[0] is None or ds[0] == 0
        last_zero = len(ds) > 1 and (ds[-1] is None or ds[-1] == 0)
        if first_empty != last_zero:
            convention, assumed = ("previous" if first_empty else "next"), " (decided by the first/last row)"
        else:
            convention, assumed = "next", " (undecided: phyphox's convention assumed)"
    return convention, f"{how}{assumed}", max(nxt, prev) * 2 >= len(pairs)


def _timed_events(
    table: Table,
    time_i: int,
    interval_i: int | None,
    notes: list[str],
    warnings: list[str],
    rejected: list[Rejected],
) -> tuple[list[float], list[int]]:
    """Onset times (s) from the event-time column, checked against the interval column if any
    (in the convention the column is found to follow, `_timed_convention`)."""
    cols = table.columns
    scale = seconds_per_unit(table, cols[time_i], notes)
    iscale = seconds_per_unit(table, cols[interval_i], notes) if interval_i is not None else 1.0
    rows = [
        (
            line,
            None if values[time_i] is None else values[time_i] * scale,
            None if interval_i is None or values[interval_i] is None else values[interval_i] * iscale,
        )
        for line, values in table.rows
    ]
    rows = _unswap(rows, notes)
    convention, how, agrees = _timed_convention(rows) if interval_i is not None else (None, "", True)
    times: list[float] = []
    lines: list[int] = []
    for line, t, dt in rows:
        if t is None:
            rejected.append(Rejected(math.nan, "no event time in this row", line))
            continue
        if times and t == times[-1]:
            rejected.append(Rejected(t, f"duplicate of line {lines[-1]} (same event time)", line))
        elif times and t < times[-1]:
            rejected.append(
                Rejected(t, f"before the previous event at {times[-1]:.6f} s (negative interval)", line)
            )
        elif times and convention == "previous" and dt is not None and dt == 0:
            rejected.append(
                Rejected(t, "interval 0.000 s since the previous row: a duplicate or spurious row", line)
            )
        else:
            times.append(t)
            lines.append(line)
    notes.append(f"onset times from column {cols[time_i].header!r}")
    if convention is not None:
        col = cols[interval_i].header
        notes.append(f"interval column {col!r} read as {CONVENTIONS[convention]}: {how}")
        last_t, last_dt = rows[-1][1], rows[-1][2]
        if convention == "next" and last_t is not None and last_dt:
            notes.append(
                f"the last row's interval {last_dt:.6f} s is to an event the export does not list (a shortened "
                "export): not read as an onset"
            )
        if not agrees:
            warnings.append(
                f"interval column {col!r} agrees with the event times in neither convention ({how}): "
                "the event times are read, the intervals are not"
            )
        else:
            warnings += _interval_disagreements(rows, convention)
    return times, lines


def _unswap(rows: list, notes: list[str]) -> list:
    """Rows with two adjacent valid onsets in reversed order put back in time order, noted.

    A pair is a swap when, exchanged, it fits between its neighbours and the three
    intervals around it stay within a factor 2 of each other (successive flights of a
    ball differ by its e, above 0.5); otherwise the later row stays a stray (rejected as
    a negative interval), as a row 1 ms before a real onset must."""
    rows = list(rows)
    k = 0
    while k + 1 < len(rows):
        (la, ta, _), (lb, tb, _) = rows[k], rows[k + 1]
        if ta is not None and tb is not None and tb < ta:
            before = rows[k - 1][1] if k > 0 else None
            after = rows[k + 2][1] if k + 2 < len(rows) else None
            gaps = [ta - tb]
            if before is not None:
                gaps.append(tb - before)
            if after is not None:
                gaps.append(after - ta)
            if len(gaps) > 1 and min(gaps) > 0 and min(gaps) >= 0.5 * max(gaps):
                rows[k], rows[k + 1] = rows[k + 1], rows[k]
                notes.append(
                    f"lines {la} and {lb}: rows out of order (event times {ta:.6f} s and {tb:.6f} s): "
                    "put back in time order, both kept"
                )
                k += 2
                continue
        k += 1
    return rows


def _interval_disagreements(rows, convention: str) -> list[str]:
    """A warning per row whose interval disagrees with the event times under `convention`."""
    out = []
    for k, (line, t, dt) in enumerate(rows):
        other = k + 1 if convention == "next" else k - 1
        if dt is None or t is None or not 0 <= other < len(rows) or rows[other][1] is None:
            continue
        difference = rows[other][1] - t if convention == "next" else t - rows[other][1]
        if not _agree(dt, difference):
            which = "to the next row" if convention == "next" else "since the previous row"
            out.append(
                f"line {line}: interval {dt:.6f} s ({which}) disagrees with the event times ({difference:.6f} s)"
            )
    return out


def _cumulated_events(
    table: Table, interval_i: int, notes: list[str], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """Onset times (s) by cumulating the interval column, the first event at t = 0.

    The convention is read from the ends: an empty (or 0) first row is the first event of
    a since-the-previous column; a 0 (or empty) last row is the last event of a
    to-the-next column (phyphox's). The times are the same either way; only the lines the
    onsets are attributed to differ."""
    cols = table.columns
    scale = seconds_per_unit(table, cols[interval_i], notes)
    entries = [(line, None if v[interval_i] is None else v[interval_i] * scale) for line, v in table.rows]
    first_empty = entries[0][1] is None or entries[0][1] == 0
    last_zero = len(entries) > 1 and (entries[-1][1] is None or entries[-1][1] == 0)
    if last_zero and not first_empty:
        convention, how = "next", "the last row is 0"
    elif first_empty and not last_zero:
        convention, how = "previous", "the first row is empty or 0"
    else:
        convention = "previous"
        how = (
            "undecided ("
            + ("an empty first row and a 0 last row" if first_empty else "no empty or 0 end row")
            + "): read as since-the-previous; the onset times are the same in either convention, only the "
            "lines they are reported on differ"
        )
    times, lines = [0.0], [entries[0][0]]
    if convention == "next":
        steps = [(line, dt, entries[k + 1][0]) for k, (line, dt) in enumerate(entries[:-1])]
    else:
        steps = [(line, dt, line) for line, dt in (entries[1:] if first_empty else entries)]
    t = 0.0
    for line, dt, at in steps:
        if dt is None:
            rejected.append(Rejected(math.nan, "no interval in this row", line))
        elif dt == 0:
            rejected.append(Rejected(t, "interval 0.000 s: a duplicate or spurious row", at))
        elif dt < 0:
            rejected.append(Rejected(math.nan, f"negative interval {dt:.6f} s", line))
        else:
            t += dt
            times.append(t)
            lines.append(at)
    notes.append(
        f"onset times by cumulating column {cols[interval_i].header!r} (the first event at t = 0; "
        "the clock offset is unknown anyway)"
    )
    notes.append(f"interval column read as {CONVENTIONS[convention]}: {how}")
    return times, lines


def _leave_out_strays(
    times: list[float], lines: list[int], rejected: list[Rejected]
) -> tuple[list[float], list[int]]:
    """The onsets without the stray ones (each added to `rejected` with its reason).

    An onset between the first and the last is stray when the interval ratios are broken
    at two pairs or more (`ratio_chain`) and leaving it out mends at least two of them,
    at most one more bounce then inferred missing (the stray sounded where a quiet bounce
    went unheard). Only an onset that touches a broken pair is tried. The best such onset
    goes first (fewest broken pairs left, then fewest bounces missing, then the smallest
    mismatch); at most `MAX_STRAYS`.

    Up to `EXACT_STRAYS` onsets each candidate is tried on the chain re-read without it
    (`ratio_chain`, its restitution re-estimated). A longer sequence is searched in linear
    time: each candidate is tried with the chain's restitution held (`_LocalChain`:
    leaving out one onset then changes the chain only near it; the median of hundreds of
    ratios barely moves), and the best that still passes when the chain is re-read
    without it (of the `MAX_REREAD` best) is left out. A sequence whose intervals do not decay even without
    `MAX_STRAYS` onsets (`_never_decays`) is searched for none: the gate refuses it.
    """
    t, ln = list(times), list(lines)
    if _never_decays(t):
        return t, ln
    for _ in range(MAX_STRAYS):
        if len(t) < 5:
            break
        chain = ratio_chain(t)
        broken = int(chain.broken.sum())
        if broken < 2:
            break
        found = _best_stray(np.asarray(t, dtype=float), chain, broken)
        if found is None:
            break
        j, after = found
        more = "; a quiet bounce near it went unheard" if after.missed > chain.missed else ""
        rejected.append(
            Rejected(
                t[j],
                f"a stray onset between two bounces, left out: without it the interval ratios form one "
                f"bouncing ball's chain again (e = {after.restitution:.3f}; {broken} broken ratio pairs -> "
                f"{int(after.broken.sum())}){more}",
                ln[j],
            )
        )
        del t[j], ln[j]
    return t, ln


def _never_decays(times) -> bool:
    """Whether the intervals of `times` (s) do not decay however `MAX_STRAYS` onsets are left
    out: at least half the successive ratios would stay at 1 or above (`bounce_problems`'
    test). Leaving out one onset replaces three ratios by two, so `MAX_STRAYS` of them
    remove at most 3 of the ratios ≥ 1 each and add at most 2 below 1."""
    interval = np.diff(np.asarray(times, dtype=float))
    if len(interval) < 2 or np.any(interval <= 0):
        return False
    ratio = interval[1:] / interval[:-1]
    up, down = int(np.sum(ratio >= 1.0)), int(np.sum(ratio < 1.0))
    return up - 3 * MAX_STRAYS >= down + 2 * MAX_STRAYS + 1


def _best_stray(t: np.ndarray, chain, broken: int):
    """(index, the chain without it) of the stray onset of `t` (s) to leave out first, or
    None (see `_leave_out_strays`); `chain`: `ratio_chain(t)`, broken at `broken` pairs."""
    flag = np.concatenate([[False], chain.broken, [False]])  # flag[p + 1]: pair p is broken
    candidates = np.arange(1, len(t) - 1)  # onset j touches pairs j - 2, j - 1 and j
    candidates = candidates[flag[candidates - 1] | flag[candidates] | flag[candidates + 1]]
    missed = chain.missed

    def passes(left: int, more: int) -> bool:
        return left <= broken - 2 and more <= missed + 1

    if len(t) <= EXACT_STRAYS or not math.isfinite(chain.restitution):
        best = None
        for j in candidates.tolist():  # each candidate's chain re-read: its restitution re-estimated
            after = ratio_chain(np.delete(t, j))
            key = (int(after.broken.sum()), after.missed, float(after.mismatch.sum()))
            if passes(*key[:2]) and (best is None or key < best[0]):
                best = (key, j, after)
        return None if best is None else best[1:]
    left, more, mismatch = _LocalChain(t, chain).without(candidates)
    ok = (left <= broken - 2) & (more <= missed + 1)
    order = candidates[ok][np.lexsort((candidates[ok], mismatch[ok], more[ok], left[ok]))]
    for j in order[:MAX_REREAD].tolist():
        after = ratio_chain(np.delete(t, j))  # the best first, re-read
        if passes(int(after.broken.sum()), after.missed):
            return j, after
    return None


class _LocalChain:
    """The ratio chain of onsets `t` (s) without one of them, its restitution held.

    Leaving out onset j merges intervals j − 1 and j; the chain before is unchanged, and
    after it the spans are chosen again only until they agree with the chain's own (from
    there on the same intervals give the same spans, `chain_spans`). So each candidate
    costs the few pairs around it, all candidates a step at a time, and the counts of the
    rest come from running sums."""

    def __init__(self, t: np.ndarray, chain):
        self.t, self.e = t, chain.restitution
        self.interval = np.diff(t)
        self.spans = chain.spans
        self.broken = np.concatenate([[0], np.cumsum(chain.broken)])
        self.missed = np.concatenate([[0], np.cumsum(chain.spans - 1)])
        self.mismatch = np.concatenate([[0.0], np.cumsum(chain.mismatch)])

    def _new(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Interval i of the chain without onset j (s), per candidate."""
        merged = self.t[j + 1] - self.t[j - 1]
        after = self.interval[np.minimum(i + 1, len(self.interval) - 1)]
        return np.where(i < j - 1, self.interval[i], np.where(i == j - 1, merged, after))

    def without(self, j: np.ndarray):
        """Broken pairs, bounces missing and summed mismatch of the chain without onset j,
        for each j of `j` (1 ≤ j ≤ len(t) − 2), its restitution held."""
        pairs = len(self.interval) - 2  # pairs of the shortened chain
        sums = span_sums(self.e)
        p = np.maximum(j - 2, 0)
        state = np.where(j >= 2, self.spans[p], 1)
        broken, missed, mismatch = self.broken[p], self.missed[p + 1], self.mismatch[p]
        out = [np.zeros(len(j), dtype=int), np.zeros(len(j), dtype=int), np.zeros(len(j))]
        active = np.arange(len(j))
        while len(active):
            state, error = chain_steps(self._new(p, j), self._new(p + 1, j), state, self.e, sums)
            broken, mismatch, p = broken + (error > RATIO_TOLERANCE), mismatch + error, p + 1
            synced = p >= j
            synced[synced] = state[synced] == self.spans[np.minimum(p[synced] + 1, len(self.spans) - 1)]
            done = synced | (p >= pairs)
            missed = missed + np.where(synced, 0, state - 1)
            tail = np.where(synced, p + 1, len(self.spans))  # the chain's own from there on
            for k, (total, value) in enumerate(
                ((self.broken, broken), (self.missed, missed), (self.mismatch, mismatch))
            ):
                rest = total[-1] - total[np.minimum(tail, len(total) - 1)]
                out[k][active[done]] = (value + np.where(synced, rest, 0))[done]
            keep = ~done
            active, j, p, state = active[keep], j[keep], p[keep], state[keep]
            broken, missed, mismatch = broken[keep], missed[keep], mismatch[keep]
        return out


def _late_start(times: np.ndarray, x0: float, drag: float | None, notes: list[str], warnings: list[str]):
    """The release height to write, m: `x0`, or where the export starts n bounces late, the
    apex before its first recorded bounce (see `import_phyphox`), noted and warned.

    Without `drag` the model is drag-free with the ratio chain's e (drag shortens the
    flights and reads e a little low, in about equal measure for the first flight): the
    first interval T1 (s) implies an apex h1 = g T1² / (8 e²) before the first recorded
    bounce, and n is the one of 0…`MAX_LATE` with h1 closest to x0·e^(2n) (in log). With
    `drag` k (s/m) the flights are those of quadratic drag, with a restitution from the
    interval pairs under that drag."""
    if len(times) < 3:
        return x0
    chain = ratio_chain(times)
    e = chain.restitution
    if not (math.isfinite(e) and 0 < e < 1) or x0 <= 0:
        return x0
    first = float(times[1] - times[0])
    if drag:
        e = _drag_restitution(times, chain, drag)
        apexes, h = [], x0
        for _ in range(MAX_LATE + 1):
            h = _apex(e * _fall_speed(h, drag), drag)
            apexes.append(h)
        errors = [abs(math.log(first / _flight(a, drag))) for a in apexes]
        n = int(np.argmin(errors))
        start = x0 if n == 0 else apexes[n - 1]
        implied = _height_of_flight(first, drag) if n == 0 else None
        model = f"quadratic drag k = {drag:g} s/m, e = {e:.4f} from the interval pairs under it"
    else:
        implied = DEFAULT_GRAVITY * first**2 / (8.0 * e**2)
        errors = [abs(math.log(implied / (x0 * e ** (2 * n)))) for n in range(MAX_LATE + 1)]
        n = int(np.argmin(errors))
        start = x0 * e ** (2 * n)
        model = f"no drag, the ratio chain's e = {e:.4f}"
    if n == 0:
        if implied is not None and implied > x0 / e:
            warnings.append(
                f"the first interval {first:.6f} s implies a release from {implied:.4g} m, above x0 = {x0:g} m "
                f"({model}): x0 too low, or a throw (v0 > 0)?"
            )
        return x0
    warnings.append(
        f"late start: the export starts at bounce {n + 1} ({n} bounce(s) before its first onset not recorded): "
        f"the first interval {first:.6f} s is the flight after bounce {n + 1} of a drop from x0 = {x0:g} m, "
        f"not after bounce 1 ({model}); x0 set to {start:.6g} m, the apex before the first recorded bounce"
    )
    notes.append(
        f"x0 = {start:.6g} m: the apex before the first recorded bounce (late start: the export starts at "
        f"bounce {n + 1}), from the given x0 = {x0:g} m and {model}"
        + (f" (x0 e^{2 * n})" if not drag else "")
        + "; t = 0 of the data set's drop is that apex, not the release"
    )
    return start


def _drag_restitution(times: np.ndarray, chain, drag: float) -> float:
    """The restitution of the single-flight interval pairs of `times` (s) under quadratic drag
    `drag` (s/m): the take-off speed of a flight over the landing speed of the one before."""
    interval = np.diff(np.asarray(times, dtype=float))
    values = []
    for k in range(len(interval) - 1):
        if chain.spans[k] == 1 and chain.spans[k + 1] == 1 and not chain.broken[k]:
            before, after = _height_of_flight(interval[k], drag), _height_of_flight(interval[k + 1], drag)
            values.append(_rise_speed(after, drag) / _fall_speed(before, drag))
    return float(np.median(values)) if values else chain.restitution


def _fall_speed(h: float, k: float) -> float:
    """Speed (m/s) after falling from rest through h (m) under quadratic drag k (s/m)."""
    if k * math.sqrt(DEFAULT_GRAVITY * max(h, 0.0)) < 1e-7:
        return math.sqrt(2.0 * DEFAULT_GRAVITY * max(h, 0.0))
    return math.sqrt(-math.expm1(-2.0 * DEFAULT_GRAVITY * k * k * h)) / k


def _rise_speed(h: float, k: float) -> float:
    """Take-off speed (m/s) that rises to h (m) under quadratic drag k (s/m)."""
    if k * math.sqrt(DEFAULT_GRAVITY * max(h, 0.0)) < 1e-7:
        return math.sqrt(2.0 * DEFAULT_GRAVITY * max(h, 0.0))
    return math.sqrt(math.expm1(2.0 * DEFAULT_GRAVITY * k * k * h)) / k


def _apex(u: float, k: float) -> float:
    """Apex height (m) of a take-off at u (m/s) under quadratic drag k (s/m)."""
    if k * u < 1e-7:
        return u * u / (2.0 * DEFAULT_GRAVITY)
    return math.log1p((k * u) ** 2) / (2.0 * DEFAULT_GRAVITY * k * k)


def _flight(h: float, k: float) -> float:
    """Flight time (s), floor to floor, of a bounce to apex h (m) under quadratic drag k (s/m)."""
    g = DEFAULT_GRAVITY
    if k * math.sqrt(g * max(h, 0.0)) < 1e-7:
        return 2.0 * math.sqrt(2.0 * max(h, 0.0) / g)
    y = g * k * k * h
    z = math.expm1(y)
    rise = math.atan(math.sqrt(math.expm1(2.0 * y))) / (g * k)
    fall = math.log1p(z + math.sqrt(z * (z + 2.0))) / (g * k)  # acosh(exp(y)), accurate for small y
    return rise + fall


def _height_of_flight(flight: float, k: float) -> float:
    """The apex height (m) of a flight of `flight` s under quadratic drag k (s/m) (bisection)."""
    lo, hi = 0.0, 1.0
    while _flight(hi, k) < flight:
        hi *= 2.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _flight(mid, k) < flight else (lo, mid)
    return 0.5 * (lo + hi)


# -- the command line --------------------------------------------------------------------


def _no_arguments(parser) -> None:
    """phyphox takes only the options every importer takes."""


def _run(args) -> ImportResult:
    return import_phyphox(args.source, **common_keywords(args))


#: `jaxunilat import phyphox`.
PHYPHOX = Importer(
    name="phyphox",
    aliases=(),
    summary="impact onsets from a phyphox Acoustic Stopwatch or (In)elastic collision export",
    description="Read a phyphox export (CSV with comma, semicolon or tab separators and decimal point or "
    "comma, detected; or .xlsx with openpyxl): the event-time column if present, else the cumulated "
    "intervals. Rows with a zero or negative interval (duplicates) and junk rows after the data are left "
    "out and reported; intervals that break the smooth decay (echoes, missed bounces) are kept and "
    "reported as warnings, for a robust fit. Writes observe = impacts.",
    source_help="the export, .csv or .xlsx (only read)",
    x0_help=X0_IMPACTS,
    noise_help="onset-time standard deviation, s (default: none, so a fit estimates it from its residuals)",
    add_arguments=_no_arguments,
    run=_run,
)
