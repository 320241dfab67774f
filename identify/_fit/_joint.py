"""Several data sets in one fit: the joint parameter vector and its batched evaluator.

**Layout.** Each data set f is predicted from its own vector
z_f = (log κ, log k_r, log k_drag, x0, v0, offset, scale, level) (`PARAMETERS`). In a
joint fit some of these entries are *shared* (one value for every file: the contact
parameters and the drag) and the others are *local* (one value per file: the release
state, the clock offset and a trace's length scale and level). The joint vector is

    z = (shared entries, in PARAMETERS order) + (file 0's local entries) + (file 1's …) + …

so a fit of one file with the default layout has exactly z = z_0. `Layout.index[f]`
holds the joint indices that make z_f = z[index[f]].

**Evaluation.** Data sets of one structure (scene, observation type, law) form a
*group*; a group's problems are padded to the same number of observations and
stacked, and one compiled call (`evaluate_rows`) runs every file's point and
finite-difference neighbours in one sequential loop: a fit of 30 files compiles once,
not 30 times. When a file's point itself fails, the neighbours are not run: the point
is rejected whatever they give (the failing trial steps of a fit are the runs that go to
`max_steps`, each the cost of hundreds of ordinary ones). A file's neighbours only perturb the joint entries that file depends
on, so a file costs 1 + 2q runs (q: its free entries other than the closed-form ones) and
the Jacobian is block-sparse: shared columns have a block from every file, local columns
only from their own.

**Closed-form columns.** Entries the prediction is linear in take no runs: the clock
offset of impact onsets (onsets + offset: column 1/σ) and a trace's `level` and `scale`
(level + scale · x_model: columns 1/σ and x_model/σ, with x_model = (prediction − level)/
scale read off the point's own run). They are exact, not differences.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import numpy as np

from jaxunilat import NoClosedFormError
from jaxunilat._internal import kept_call

from ._initial import CONTACT_TIME_GUESS
from ._problem import LAW_MODELS, PARAMETERS, Problem, evaluate_rows, stack_problems

#: Parameters that shift every prediction of impact onsets by their own value (onsets +
#: offset): their Jacobian column is 1/σ exactly, so they take no runs (traces: differenced).
SHIFTS = ("offset",)
#: A trace's linear entries (prediction = level + scale · x_model): closed-form columns.
TRACE_LINEAR = ("scale", "level")
#: sd of log t_c in the steering prior: the 0.5–2 ms prior as ±2 sd around 1 ms.
PRIOR_SD = math.log(2.0) / 2.0


@dataclasses.dataclass(frozen=True)
class Layout:
    """Which entries of z are shared across files and which are per file.

    **Fields:** `n_files`; `shared`, the names with one joint entry; `local`, the names
    with one entry per file (together, all of `PARAMETERS`).
    """

    n_files: int
    shared: tuple[str, ...] = ("kappa", "k_r", "drag")
    local: tuple[str, ...] = ("x0", "v0", "offset", "scale", "level")

    @property
    def size(self) -> int:
        """Length of the joint vector."""
        return len(self.shared) + self.n_files * len(self.local)

    @functools.cached_property
    def index(self) -> np.ndarray:
        """(files, len(PARAMETERS)) joint indices: z_f = z[index[f]] (computed once: every
        evaluation reads it)."""
        out = np.zeros((self.n_files, len(PARAMETERS)), dtype=int)
        for f in range(self.n_files):
            for i, name in enumerate(PARAMETERS):
                if name in self.shared:
                    out[f, i] = self.shared.index(name)
                else:
                    out[f, i] = len(self.shared) + f * len(self.local) + self.local.index(name)
        return out

    def names(self) -> list[tuple[str, int | None]]:
        """(parameter name, file or None when shared) of every joint entry."""
        out = [(n, None) for n in self.shared]
        for f in range(self.n_files):
            out += [(n, f) for n in self.local]
        return out

    def join(self, per_file: list[np.ndarray]) -> np.ndarray:
        """A joint vector from per-file vectors z_f (shared entries from file 0)."""
        z = np.zeros(self.size)
        for f, zf in enumerate(per_file):
            z[self.index[f]] = zf
        return z

    def split(self, z: np.ndarray) -> np.ndarray:
        """(files, len(PARAMETERS)): every file's z_f."""
        return np.asarray(z)[self.index]


@dataclasses.dataclass
class Group:
    """Files of one structure, stacked for one compiled call."""

    files: list[int]
    problem: Problem  # stacked: a leading file axis on every array leaf
    rows: list[int]  # each file's real observation count (the rest is padding)
    y_obs: np.ndarray | None = None  # host copy of the stacked observations (closed-form columns)


def make_groups(problems: list[Problem], rows: list[int]) -> list[Group]:
    """Stack problems that share their static structure (already padded alike)."""
    keys: dict = {}
    for f, p in enumerate(problems):
        key = (p.scene, p.observe, p.has_drag, p.n_events, p.tol, p.max_steps, p.law, p.shift_trace)
        key = key + (int(np.asarray(p.t_obs).shape[0]),)
        keys.setdefault(key, []).append(f)
    return [
        Group(
            files=fs,
            problem=stack_problems([problems[f] for f in fs]),
            rows=[rows[f] for f in fs],
            y_obs=np.stack([np.asarray(problems[f].y_obs, dtype=float) for f in fs]),
        )
        for fs in keys.values()
    ]


@dataclasses.dataclass
class CallCount:
    """Compiled calls made, shared by an evaluator and every evaluator derived from it."""

    n: int = 0


@dataclasses.dataclass(frozen=True)
class JointEvaluator:
    """r and J of every file at a joint point: one compiled call per group.

    **Fields:** the `groups`, the `layout`, the `free` joint indices (the Jacobian's
    columns, in this order), the finite-difference `steps` per joint entry, the files'
    `masses`, the `prior` switch and law (the steering prior on log t_c, one row per
    distinct κ/k_r pair), and `counter` (compiled calls made: `calls`).

    Residual rows are every file's real observations in file order, then the prior's
    rows when `prior` is on. `transforms` maps a file to a host-side map
    (r, J) → (r′, J′) of its rows (the restitution-scatter error model of impact onsets,
    `identify._fit._robust.RatioResiduals`); it changes what is fitted, not what is compiled.

    Frozen: a stage that fits other rows (without the prior, or with the log-ratio
    rows) derives its own evaluator with `with_`; the derived ones share the call count.
    """

    groups: list[Group]
    layout: Layout
    free: list[int]
    steps: np.ndarray
    masses: np.ndarray
    sigmas: np.ndarray
    law: str = "kelvin-voigt"
    prior: bool = True
    speed: float = 1.0
    transforms: dict = dataclasses.field(default_factory=dict)
    counter: CallCount = dataclasses.field(default_factory=CallCount)

    @property
    def calls(self) -> int:
        """Compiled calls made by this evaluator and every one derived from it."""
        return self.counter.n

    def with_(self, **changes) -> JointEvaluator:
        """This evaluator with `changes` to its fields (e.g. `prior=False`), sharing its call count."""
        return dataclasses.replace(self, **changes)

    def _file_columns(self, f: int) -> tuple[list[int], list[tuple[int, str]]]:
        """Free joint entries file f depends on: (differenced, closed form as (entry, name))."""
        idx = self.layout.index[f]
        # Only impact onsets are shifted by the offset; a trace's samples are taken at
        # t − offset, so its column is −v(t)/σ and is differenced like the rest (a 1/σ
        # column there stopped `--fit offset` on a clean trace at "no decrease found").
        observe = self._observe(f)
        closed_here = SHIFTS if observe == "impacts" else TRACE_LINEAR if observe == "trace" else ()
        fd, closed = [], []
        for j in self.free:
            where = np.flatnonzero(idx == j)
            if where.size:
                name = PARAMETERS[where[0]]
                if name in closed_here:
                    closed.append((j, name))
                else:
                    fd.append(j)
        return fd, closed

    def _group_of(self, f: int) -> tuple[Group, int]:
        """File f's group and its position there."""
        for g in self.groups:
            if f in g.files:
                return g, g.files.index(f)
        raise AssertionError(f)

    def _observe(self, f: int) -> str:
        """File f's observation kind (from its group's stacked problem)."""
        return self._group_of(f)[0].problem.observe

    def _closed_column(self, f: int, name: str, r0: np.ndarray, z_f: np.ndarray) -> np.ndarray:
        """File f's exact Jacobian column of a closed-form entry at its point z_f (residuals r0).

        The offset of impact onsets and a trace's level enter as + value: 1/σ. A trace's
        scale multiplies the simulated position: x_model/σ, where x_model = (prediction −
        level)/scale and prediction = σ·r0 + data.
        """
        sigma = float(self.sigmas[f])
        if name != "scale":
            return np.full(len(r0), 1.0 / sigma)
        g, k = self._group_of(f)
        y = g.y_obs[k, : len(r0)]
        level, scale = z_f[PARAMETERS.index("level")], z_f[PARAMETERS.index("scale")]
        return (sigma * r0 + y - level) / (scale * sigma)

    @property
    def rows(self) -> int:
        """Runs per file in a compiled call: the point and two neighbours per differenced entry."""
        return 1 + 2 * max(len(self._file_columns(f)[0]) for f in range(self.layout.n_files))

    def _prior_pairs(self) -> list[tuple[int, int, int]]:
        """(file, κ index, k_r index) of every distinct contact-parameter pair."""
        seen, out = set(), []
        for f in range(self.layout.n_files):
            pair = (int(self.layout.index[f, 0]), int(self.layout.index[f, 1]))
            if pair not in seen:
                seen.add(pair)
                out.append((f, *pair))
        return out

    def _prior_row(self, f: int, log_kappa: float, log_k_r: float) -> float:
        t_c = contact_time_of(self.law, log_kappa, log_k_r, float(self.masses[f]), self.speed, floor=True)
        return (math.log(max(t_c, 1e-300)) - math.log(CONTACT_TIME_GUESS)) / PRIOR_SD

    def prior_rows(self, z: np.ndarray) -> np.ndarray:
        """The steering prior's residuals (log t_c − log t_c,prior)/sd."""
        return np.asarray([self._prior_row(f, z[ik], z[ir]) for f, ik, ir in self._prior_pairs()])

    def _run(
        self, per_file_rows: list[np.ndarray], count: bool = True, skip: bool = True
    ) -> tuple[list, list]:
        """Residuals (rows, n_f) and ok (rows,) of every file for its (rows, len(PARAMETERS)) points
        (`count`: add the call to `calls`; `skip`: see `evaluate_rows`)."""
        res: list = [None] * self.layout.n_files
        oks: list = [None] * self.layout.n_files
        for g in self.groups:
            zs = np.stack([per_file_rows[f] for f in g.files])
            r, ok = kept_call(
                "identify.evaluate_rows", evaluate_rows, (g.problem, jax.device_put(zs), np.asarray(skip))
            )
            r, ok = np.asarray(r), np.asarray(ok)
            for k, f in enumerate(g.files):
                res[f], oks[f] = r[k, :, : g.rows[k]], ok[k]
        self.counter.n += int(count)
        return res, oks

    def warm(self, z: np.ndarray) -> None:
        """Compile every group's program by one run at the joint point z (not counted in
        `calls`): the same shapes as every later call, so nothing compiles again."""
        z = np.asarray(z, dtype=float)
        rows = self.rows
        self._run(
            [np.repeat(z[self.layout.index[f]][None, :], rows, axis=0) for f in range(self.layout.n_files)],
            False,
        )

    def __call__(self, z: np.ndarray):
        """(r, J, ok) at the joint point z; J has one column per `free` entry."""
        z = np.asarray(z, dtype=float)
        rows = self.rows
        points, plans = [], []
        for f in range(self.layout.n_files):
            idx = self.layout.index[f]
            base = z[idx]
            fd, closed = self._file_columns(f)
            pts = np.repeat(base[None, :], rows, axis=0)
            for k, j in enumerate(fd):
                pts[1 + 2 * k, idx == j] += self.steps[j]
                pts[2 + 2 * k, idx == j] -= self.steps[j]
            points.append(pts)
            plans.append((fd, closed, base))
        res, oks = self._run(points)
        blocks_r, blocks_j, ok = [], [], True
        for f, (fd, closed, base) in enumerate(plans):
            r = res[f]
            jac = np.zeros((r.shape[1], len(self.free)))
            for k, j in enumerate(fd):
                jac[:, self.free.index(j)] = (r[1 + 2 * k] - r[2 + 2 * k]) / (2 * self.steps[j])
            for j, name in closed:
                jac[:, self.free.index(j)] = self._closed_column(f, name, r[0], base)
            if f in self.transforms:
                r0, jac = self.transforms[f](r[0], jac)
            else:
                r0 = r[0]
            blocks_r.append(r0)
            blocks_j.append(jac)
            ok = ok and bool(np.all(oks[f][: 1 + 2 * len(fd)]))
        r = np.concatenate(blocks_r)
        jac = np.concatenate(blocks_j)
        if self.prior:
            r = np.concatenate([r, self.prior_rows(z)])
            jac = np.concatenate([jac, self._prior_jacobian(z)])
        return r, jac, ok

    def _prior_jacobian(self, z: np.ndarray, h: float = 1e-6) -> np.ndarray:
        """Central differences of each prior row in its own κ and k_r entries."""
        jac = np.zeros((len(self._prior_pairs()), len(self.free)))
        for row, (f, ik, ir) in enumerate(self._prior_pairs()):
            for j, (dk, dr) in ((ik, (h, 0.0)), (ir, (0.0, h))):
                if j in self.free:
                    up = self._prior_row(f, z[ik] + dk, z[ir] + dr)
                    down = self._prior_row(f, z[ik] - dk, z[ir] - dr)
                    jac[row, self.free.index(j)] = (up - down) / (2 * h)
        return jac

    def _transformed(self, f: int, r: np.ndarray) -> np.ndarray:
        if f not in self.transforms:
            return r
        return self.transforms[f](r, _no_jacobian(len(r)))[0]

    def values(self, zs: list[np.ndarray]) -> list[tuple[np.ndarray, bool]]:
        """Residuals at several joint points (batched by the compiled row count)."""
        rows = self.rows
        out = []
        for k in range(0, len(zs), rows):
            chunk = [np.asarray(z, dtype=float) for z in zs[k : k + rows]]
            padded = chunk + [chunk[-1]] * (rows - len(chunk))
            points = [np.stack([z[self.layout.index[f]] for z in padded]) for f in range(self.layout.n_files)]
            res, oks = self._run(points, skip=False)
            for i, z in enumerate(chunk):
                r = np.concatenate([self._transformed(f, res[f][i]) for f in range(self.layout.n_files)])
                if self.prior:
                    r = np.concatenate([r, self.prior_rows(z)])
                out.append((r, bool(all(oks[f][i] for f in range(self.layout.n_files)))))
        return out


def _no_jacobian(n: int) -> np.ndarray:
    return np.zeros((n, 0))


def contact_time_of(
    law: str, log_kappa: float, log_k_r: float, mass: float, speed: float, *, floor: bool = False
) -> float:
    """Contact time, s, of the law at (κ, k_r), on the host: the law's closed form
    (`contact_time` with numpy), or where damping has none (Hunt–Crossley) its undamped
    time at impact speed `speed` (m/s). A contact with no time (Kelvin–Voigt overdamped:
    inf) is, with `floor`, finite and huge (π/√1e-300, as if ω_d² = 1e-300), so that
    the prior's residual and its difference quotient stay finite."""
    model = LAW_MODELS[law]
    kappa, k_r = math.exp(log_kappa), math.exp(log_k_r)
    try:
        t_c = float(model.contact_time(kappa, k_r, mass, speed, xp=np))
    except NoClosedFormError:
        return float(model.contact_time(kappa, None, mass, speed, xp=np))
    return math.pi / math.sqrt(1e-300) if floor and not math.isfinite(t_c) else t_c
