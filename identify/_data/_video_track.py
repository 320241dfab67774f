"""Following the ball through the unique frames of a clip: one blob per frame, in free flight.

1. **Background:** the per-pixel median of (at most `BACKGROUND_FRAMES`) unique frames;
   after the first pass, along the ball's way, the median of the frames that show the ball
   elsewhere (`background_without_ball`: a ball resting for half the clip is no background).
2. **Candidates:** per frame, the connected regions (closed over 3×3, at least `MIN_AREA`
   px) whose contrast exceeds `THRESHOLD` times the frame's median colour distance from the
   background (at least `MIN_CONTRAST` gray levels); the `MAX_CANDIDATES` with the most
   contrast, each with its contrast-weighted centroid, area, core colour and a shadow score
   (darker than the background with the background's own hue). The first pass takes as
   contrast the colour distance that no shadow explains (`_unshadowed`: a shadow touching
   the ball stays out of its blob), on frames at most `VOTE_RATE` a second; the second,
   once the ball's colour is known, only the part that reads as the ball's coverage
   (`coverage`: a shadow, or a hand of another hue, no longer merges with the ball), and a
   blob much larger than its fully covered core (a ball in a hand of nearly its hue) is cut
   along the core's margin (`_split_cores`).
3. **Gravity in pixels:** every chain of candidates over five successive frames whose three
   triples move, turn downwards and accelerate alike, each triple's blobs of alike area
   (`AREA_ALIKE`), votes for its vertical acceleration;
   the votes' peak is the first estimate of g in px/s² (the parabola fits refine it). A clip
   faster than `VOTE_RATE` frames/s votes on every k-th frame (at 240 frames/s gravity moves
   the ball by a tenth of a pixel from frame to frame).
4. **The path:** a second-order Viterbi choice of one candidate (or none) per frame that
   minimises, over the clip, the squared deviation from constant-acceleration motion
   (capped at `MOTION_CAP`), the appearance cost (shadow, size and colour unlike the
   ball's) and `MISSING_COST` per frame without one. In the second pass, three positions
   at rest (held, resting) and a bounce (the floor pushing the ball up) cost less.
5. **Sub-pixel centre:** the centroid of the ball's coverage around the chosen blob, each
   pixel's coverage read against the ball's own shading near it, saturated at `SATURATION`,
   the faint halo below `HALO` left out and a highlight enclosed by the ball counted as
   covered (`measure`); its uncertainty from the frame's noise; the apparent diameter as the
   extent of the half-covered pixels across the motion (motion blur stretches the ball
   along it only). With a rolling shutter this is the ball's centre when the row through it
   was exposed (the trace adds the readout's share to the frame's time).

Coordinates are working-frame pixels (y down) inside this module; `track` returns source
display pixels.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import ndimage

from jaxunilat._internal import InputError

from ._video_decode import Frames
from ._video_repeats import Repeats, find_repeats

#: Frames used for the median background, at most.
BACKGROUND_FRAMES = 61
#: Where the first pass saw the ball near a pixel in this fraction of its frames or more,
#: the background there comes from the frames without it (`background_without_ball`).
BALL_OFTEN = 0.1
#: The least noise assumed, gray levels (8-bit quantisation: 1/sqrt(12)).
MIN_NOISE = 0.3
#: A pixel is foreground when its colour distance exceeds this many times the frame's median.
THRESHOLD = 6.0
#: ... and at least this many gray levels (colour distance, 0-441).
MIN_CONTRAST = 10.0
#: The smallest candidate region, working px.
MIN_AREA = 4
#: Candidates kept per frame (those with the most contrast).
MAX_CANDIDATES = 8
#: The three accelerations of a voting chain agree within 1 px/frame² and this fraction (a
#: rolling shutter stretches a falling ball's steps and squeezes a rising one's, by tens of
#: percent at the bottom of a fall; drag bends them a little).
VOTE_ALIKE = 0.25
#: The blobs of a voting triple differ in area by at most this factor (one ball, blurred a
#: little more or less from frame to frame; a codec's speck, a shadow on the floor or the
#: hand is another object, and three such things can line up on a parabola of their own).
AREA_ALIKE = 4.0
#: Gravity is voted on frames at most this many a second (a faster clip votes on every
#: k-th frame: `gravity_votes`).
VOTE_RATE = 60.0
#: The motion cost of a triple is capped at this (an impact, a glitch).
MOTION_CAP = 9.0
#: The cost of a frame with no candidate chosen ...
MISSING_COST = 4.0
#: ... and of each triple of frames that holds one (the motion cannot be checked).
GAP_COST = 3.0
#: Three positions within this many px of each other are at rest (held, or resting) ...
REST_MOTION = 1.5
#: ... and cost at most this (once the ball's size and colour are known).
REST_COST = 1.0
#: A bounce (the middle of three positions lowest) costs at most this (once known).
BOUNCE_COST = 3.0
#: The cost of a shadow-like candidate.
SHADOW_COST = 3.0
#: A pixel counts towards the ball where its change from the background is within this
#: angle (degrees, in RGB) of the ball's colour's change.
COLOUR_CONE = 50.0
#: A shadow darkens the background by at most this fraction.
SHADOW_DEPTH = 0.6
#: The ball's own shading darkens its colour by at most this fraction (its shaded side).
BALL_SHADING = 0.3
#: The ridge on a shadow's darkening (a fraction of the background's own square norm) that
#: keeps a ball of the background's hue read as coverage, not as a brighter background.
SHADOW_RIDGE = 0.1
#: A blob more than `CORE_SPLIT` times the area of its core (coverage at least `CORE`,
#: and `CORE_MARGIN` px round it) is cut along the core's margin (`_split_cores`).
CORE = 0.75
CORE_MARGIN = 2
CORE_SPLIT = 2.5
#: A candidate whose colour differs from the ball's by this many gray levels costs 1.
COLOUR_SCALE = 25.0
#: A pixel's coverage is read against the largest within this many px (the ball's shading
#: near it) ...
SHADING_REACH = 2
#: ... taken as at least this (far from the ball, the coverage is noise).
SHADING_FLOOR = 0.7
#: Coverage below this counts for nothing, and above it in proportion (the faint halo that
#: compression and chroma subsampling leave round the ball, and noise, weigh nothing; an edge
#: profile keeps its middle).
HALO = 0.2
#: Coverage at which a pixel counts fully towards the ball's centre (a highlight no more).
SATURATION = 1.0
#: The appearance costs (size, colour) are capped at this each.
APPEARANCE_CAP = 4.0


@dataclasses.dataclass(frozen=True, eq=False)
class Track:
    """The ball in each unique frame of a clip.

    - `frames`, `repeats`: the decoded clip and its repeated frames.
    - `index`: the unique frames' indices into `frames`; `t`: their times, s (container
      clock; `Repeats.times`: put back on the source's frame grid in a clip with repeats).
    - `x`, `y`: the ball's centre, source display px (y down), NaN where not found.
    - `sigma`: the centre's uncertainty from the frame's noise, px (NaN where not found).
    - `diameter`: the apparent diameter across the motion, px; `blur`: the extent along
      the motion beyond it, px (NaN where not found).
    - `gravity_px`: g in source px/s² from the tracking votes (NaN if none).
    - `colour`: the ball's median RGB (0-255); `roi`: the region searched, source px, or None.
    - `notes`: what the tracker decided, in words.
    """

    frames: Frames
    repeats: Repeats
    index: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray
    diameter: np.ndarray
    blur: np.ndarray
    gravity_px: float
    colour: tuple[float, float, float]
    roi: tuple[float, float, float, float] | None
    notes: tuple[str, ...] = ()

    @property
    def found(self) -> np.ndarray:
        """Whether the ball was found in each unique frame."""
        return np.isfinite(self.y)


@dataclasses.dataclass
class _Candidates:
    """The candidate blobs of one frame (working px): centroid, area, contrast mass, colour,
    shadow score."""

    pos: np.ndarray
    area: np.ndarray
    mass: np.ndarray
    colour: np.ndarray
    shadow: np.ndarray


# -- colour hints --------------------------------------------------------------------------


def parse_colour(colour) -> np.ndarray | None:
    """An RGB hint (0-255 floats) from a name or '#rrggbb' (matplotlib colours), an (r, g, b)
    of 0-255 (or 0-1 floats), or a hue in degrees (a number); None for None."""
    if colour is None:
        return None
    if isinstance(colour, (int, float)) and not isinstance(colour, bool):
        import colorsys

        return 255.0 * np.asarray(colorsys.hsv_to_rgb((float(colour) % 360.0) / 360.0, 1.0, 1.0))
    if isinstance(colour, str):
        from matplotlib.colors import to_rgb

        try:
            return 255.0 * np.asarray(to_rgb(colour.strip()))
        except ValueError:
            raise InputError(
                f"color = {colour!r} is not a colour; give a name (red, white), '#rrggbb', r,g,b or a hue in degrees"
            ) from None
    rgb = np.asarray(colour, dtype=float).ravel()
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)) or rgb.min() < 0 or rgb.max() > 255:
        raise InputError(f"color = {colour!r}: an RGB colour needs three values in [0, 255]")
    return rgb * 255.0 if rgb.max() <= 1.0 and np.any(rgb % 1 != 0) else rgb


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle between colour vectors, degrees (0: the same hue and saturation)."""
    na = np.linalg.norm(a, axis=-1) + 1e-6
    nb = np.linalg.norm(b, axis=-1) + 1e-6
    cos = np.clip(np.sum(a * b, axis=-1) / (na * nb), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


# -- background and candidates ---------------------------------------------------------------


def background(rgb: np.ndarray) -> np.ndarray:
    """The per-pixel median of at most `BACKGROUND_FRAMES` frames spread over the clip, float32."""
    pick = np.unique(np.linspace(0, len(rgb) - 1, min(len(rgb), BACKGROUND_FRAMES)).round().astype(int))
    stack = rgb[pick]
    mid = (len(pick) - 1) // 2
    return np.partition(stack, mid, axis=0)[mid].astype(np.float32)


def background_without_ball(rgb: np.ndarray, found, path, bg: np.ndarray) -> np.ndarray:
    """`bg` recomputed where the ball often is, from the frames where the first pass saw it
    elsewhere: a ball that rests (or bounces low) near one place for half the clip is in
    the plain median, hidden there, and a ball over its own ghost reads as partly missing.
    Each pixel within a ball's radius of the ball's blob (its shadow and blur near it) in
    `BALL_OFTEN` or more of (at most `BACKGROUND_FRAMES`) frames where the ball was seen
    takes the median of those of them where it was not near; with fewer than 3 such
    frames, or where the ball only passes, it keeps `bg`."""
    seen = np.asarray([i for i, slot in enumerate(path) if slot < len(found[i][0].pos)], dtype=int)
    if len(seen) < 3:
        return bg
    pick = seen[
        np.unique(np.linspace(0, len(seen) - 1, min(len(seen), BACKGROUND_FRAMES)).round().astype(int))
    ]
    radius = max(2.0, math.sqrt(float(np.median([found[i][0].area[path[i]] for i in seen])) / math.pi))
    m = int(math.ceil(radius)) + 1
    h, w = bg.shape[:2]
    covered = np.zeros((len(pick), h, w), dtype=bool)
    for j, i in enumerate(pick):
        labels = found[i][1]
        rs, cs = ndimage.find_objects((labels == path[i] + 1).astype(np.int8))[0]
        box = (
            slice(max(0, rs.start - m), min(h, rs.stop + m)),
            slice(max(0, cs.start - m), min(w, cs.stop + m)),
        )
        covered[j][box] = ndimage.distance_transform_edt(labels[box] != path[i] + 1) <= radius
    rows, cols = np.nonzero(covered.mean(axis=0) >= BALL_OFTEN)
    free = ~covered[:, rows, cols]
    count = free.sum(axis=0)
    enough = count >= 3
    stack = np.sort(np.where(free[..., None], rgb[pick][:, rows, cols].astype(np.float32), np.inf), axis=0)
    k = count[enough]
    lo = np.take_along_axis(stack[:, enough], ((k - 1) // 2)[None, :, None], axis=0)[0]
    hi = np.take_along_axis(stack[:, enough], (k // 2)[None, :, None], axis=0)[0]
    out = bg.copy()
    out[rows[enough], cols[enough]] = 0.5 * (lo + hi)
    return out


def _distance(frame: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """The colour distance of each pixel from the background, 0-441."""
    d = frame.astype(np.float32) - bg
    return np.sqrt(np.einsum("...c,...c->...", d, d))


def _unshadowed(frame: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """The colour distance from the background that no shadow explains, 0-441: each pixel's
    change less its part along the background's own colour, where that part darkens it by
    at most `SHADOW_DEPTH` (a shadow keeps the background's hue; a ball that is not the
    background's colour made darker keeps most of its distance, a black one a part)."""
    d = frame.astype(np.float32) - bg
    b = np.maximum(bg, 1.0)
    beta = np.einsum("...c,...c->...", d, b) / np.einsum("...c,...c->...", b, b)
    rest = d - np.clip(beta, -SHADOW_DEPTH, 0.0)[..., None] * b
    return np.sqrt(np.einsum("...c,...c->...", rest, rest))


def coverage(pixels: np.ndarray, under: np.ndarray, colour: np.ndarray, noise: float):
    """The ball's coverage of pixels (0-1.2) and the contrast it is read with (gray levels).

    Each pixel's change from the background `under` it is split (least squares, in RGB) into
    a part along the ball's own change (`colour` - background: the coverage α) and a part
    along the background itself (β: a shadow darkens the background by β < 0): a shadow
    falling on or next to the ball, or the ball over its own shadow, no longer reads as
    the ball. β is held at 0 where it would brighten the background, and where the ball is
    no darker than the background along the background's colour (a white ball on a white
    wall: a shadow's change points away from the ball's and fails the cone below); a small
    ridge on β keeps a ball of nearly the background's hue read as coverage. A shadow darkens only the part of the background that the ball
    leaves uncovered (by `SHADOW_DEPTH` at most) and the ball's own shading darkens it by
    `BALL_SHADING` at most, so β ≥ -SHADOW_DEPTH (1 - α) - BALL_SHADING α (on that bound
    where the free split would go beyond it: a dark hand is not a deep shadow behind a
    covering ball). A pixel counts only where the shadow-corrected change points within
    `COLOUR_CONE` degrees of the ball's (a lit or shaded side of the ball), else 0 (a hand
    or an object of another hue). Also the contrast |colour - background|, gray levels: the
    coverage's noise is about noise / contrast."""
    p = pixels.astype(np.float32) - under
    c = (colour.astype(np.float32) - under).astype(np.float32)
    b = np.maximum(under.astype(np.float32), 1.0)

    def dot(u, v):
        return np.einsum("...c,...c->...", u, v)

    cc, cb, bb = np.maximum(dot(c, c), 1.0), dot(c, b), dot(b, b)
    cp, bp = dot(c, p), dot(b, p)
    ridge = SHADOW_RIDGE * bb
    det = np.maximum(cc * (bb + ridge) - cb * cb, 1e-6)
    beta = np.where(cb < 0.0, np.minimum((cc * bp - cb * cp) / det, 0.0), 0.0)
    alpha = (cp - beta * cb) / cc
    # a shadow darkens only the background the ball leaves uncovered, the ball's own shading
    # at most BALL_SHADING: beta >= -SHADOW_DEPTH (1 - alpha) - BALL_SHADING alpha
    slope = SHADOW_DEPTH - BALL_SHADING
    edge = c + slope * b
    on_edge = (dot(p + SHADOW_DEPTH * b, edge) / np.maximum(dot(edge, edge), 1.0)).astype(np.float32)
    bound = beta < -SHADOW_DEPTH + slope * alpha
    alpha = np.where(bound, on_edge, alpha)
    beta = np.where(bound, -SHADOW_DEPTH + slope * on_edge, beta)
    rest = p - beta[..., None] * b
    rr = np.sqrt(dot(rest, rest))
    cos = dot(rest, c) / (np.sqrt(cc) * np.maximum(rr, 1e-3))
    ok = cos >= math.cos(math.radians(COLOUR_CONE))
    return np.where(ok, np.clip(alpha, 0.0, 1.2), 0.0), np.sqrt(cc)


def candidates(
    frame: np.ndarray, bg: np.ndarray, roi_mask=None, colour=None
) -> tuple[_Candidates, np.ndarray, np.ndarray, float]:
    """The candidate blobs of a frame, the label image and contrast map they come from, and
    the frame's noise (gray levels). The contrast is the colour distance from the background
    that no shadow explains (`_unshadowed`: a shadow touching the ball is no part of its
    blob), or, when the ball's `colour` is known, the part of it that reads as the ball's
    coverage."""
    dist = _distance(frame, bg)
    noise = max(float(np.median(dist[::3, ::3])) / 1.5, MIN_NOISE)
    level = max(1.5 * THRESHOLD * noise, MIN_CONTRAST)
    if colour is not None:
        alpha, contrast = coverage(frame, bg, colour, noise)
        dist = alpha * contrast
    else:
        dist = _unshadowed(frame, bg)
    fg = dist > level
    if roi_mask is not None:
        fg &= roi_mask
    fg = ndimage.binary_closing(fg, structure=np.ones((3, 3), bool)) & (dist > 0.5 * level)
    if colour is not None:
        fg = _split_cores(fg, alpha)
    labels, n = ndimage.label(fg, structure=np.ones((3, 3), bool))
    flat = labels.ravel()
    w = np.where(fg, dist, 0.0).ravel()
    area = np.bincount(flat, minlength=n + 1)[1:].astype(float)
    mass = np.bincount(flat, weights=w, minlength=n + 1)[1:]
    ok = np.flatnonzero(area >= MIN_AREA)
    ok = ok[np.argsort(-mass[ok])][:MAX_CANDIDATES]
    remap = np.zeros(n + 1, dtype=np.int32)
    remap[ok + 1] = np.arange(1, len(ok) + 1)
    labels = remap[labels]
    if not len(ok):
        empty = np.zeros((0, 2))
        return (
            _Candidates(empty, np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros(0)),
            labels,
            dist,
            noise,
        )
    flat = labels.ravel()
    yy, xx = np.divmod(np.arange(flat.size), labels.shape[1])
    k = len(ok) + 1
    m = mass[ok]
    pos = np.stack(
        [
            np.bincount(flat, weights=w * xx, minlength=k)[1:] / m,
            np.bincount(flat, weights=w * yy, minlength=k)[1:] / m,
        ],
        1,
    )
    core, under = _core_colours(frame, bg, labels, dist, len(ok))
    cands = _Candidates(pos, area[ok], m, core, _shadow_score(core, under))
    return cands, labels, dist, noise


def _split_cores(fg: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """`fg` with each blob much larger than its fully covered core (at least `CORE`
    coverage, with `CORE_MARGIN` px round it) cut in two along the core's margin: a ball
    held in a hand, or touching it, whose skin reads as partial coverage (a skin colour is
    a mixture of the ball's and the wall's), becomes a blob of its own. A blob without a
    core (a ball blurred into a faint streak) or little larger than it stays whole."""
    labels, n = ndimage.label(fg, structure=np.ones((3, 3), bool))
    if not n:
        return fg
    near = ndimage.binary_dilation(fg & (alpha >= CORE), iterations=CORE_MARGIN) & fg
    area = np.bincount(labels.ravel(), minlength=n + 1)
    core = np.bincount(labels[near], minlength=n + 1)
    split = (core > 0) & (area > CORE_SPLIT * core)
    split[0] = False
    cut = split[labels] & ~near
    return fg & ~(ndimage.binary_dilation(near, structure=np.ones((3, 3), bool)) & cut)


def _core_colours(frame, bg, labels, dist, n) -> tuple[np.ndarray, np.ndarray]:
    """The median colour of each blob's more contrasted half, and of the background under it."""
    core, under = np.zeros((n, 3)), np.zeros((n, 3))
    for k, sl in enumerate(ndimage.find_objects(labels, max_label=n)):
        inside = labels[sl] == k + 1
        d = dist[sl][inside]
        top = d >= np.median(d)
        core[k] = np.median(frame[sl][inside][top], axis=0)
        under[k] = np.median(bg[sl][inside][top], axis=0)
    return core, under


def _shadow_score(colour: np.ndarray, under: np.ndarray) -> np.ndarray:
    """1 for a region darker than the background under it with the background's hue, else 0."""
    ratio = colour / np.maximum(under, 1.0)
    mean = ratio.mean(axis=1)
    flat = (ratio.max(axis=1) - ratio.min(axis=1)) < 0.12 * np.maximum(mean, 1e-3)
    return ((mean < 0.92) & flat).astype(float)


def _roi_mask(roi, frames: Frames, shape) -> np.ndarray | None:
    """The region searched as a boolean working-frame mask (`roi`: x0, y0, x1, y1 in source px)."""
    if roi is None:
        return None
    x0, y0, x1, y1 = (float(v) for v in roi)
    w, h = frames.source_size
    if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
        raise InputError(
            f"roi = {x0:g},{y0:g},{x1:g},{y1:g} is not a box inside the {w}x{h} px frame "
            "(x0, y0, x1, y1 in pixels of the picture as displayed, y down)"
        )
    (u0, u1), (v0, v1) = frames.to_work([x0, x1], [y0, y1])
    yy, xx = np.indices(shape)
    return (xx >= u0) & (xx <= u1) & (yy >= v0) & (yy <= v1)


# -- gravity from the candidates --------------------------------------------------------------


def _second_difference(p1, p2, p3, dt1, dt2):
    """The acceleration of three positions at steps dt1, dt2 (px/s²), broadcasting."""
    return 2.0 * ((p3 - p2) / dt2 - (p2 - p1) / dt1) / (dt1 + dt2)


def _triples(a, b, c, dt1, dt2, step, reach):
    """The accelerations (m, m, m, 2; px/s²) of the candidate triples of three successive
    frames, and which are plausible for a ball in flight: moving, turning downwards, no step
    longer than `reach` px, none of them a shadow, their areas alike within `AREA_ALIKE`."""
    p1, p2, p3 = a.pos[:, None, None], b.pos[None, :, None], c.pos[None, None, :]
    acc = _second_difference(p1, p2, p3, dt1, dt2)
    moving = np.linalg.norm(p3 - p1, axis=-1) * step / (dt1 + dt2) > 1.5
    near = (np.linalg.norm(p2 - p1, axis=-1) < reach) & (np.linalg.norm(p3 - p2, axis=-1) < reach)
    down = (acc[..., 1] * step**2 > 0.2) & (np.abs(acc[..., 0]) < 0.3 * acc[..., 1])
    shadow = (a.shadow[:, None, None] + b.shadow[None, :, None] + c.shadow[None, None, :]) > 0
    areas = np.broadcast_arrays(a.area[:, None, None], b.area[None, :, None], c.area[None, None, :])
    alike = np.maximum.reduce(areas) <= AREA_ALIKE * np.minimum.reduce(areas)
    return acc, moving & near & down & ~shadow & alike


def gravity_votes(cands: list[_Candidates], t: np.ndarray, reach: float) -> float:
    """g in working px/s² (NaN if fewer than 3 frames vote): the peak (5 % bins) of the log
    vertical accelerations of the candidate chains over five successive frames whose three
    triples are plausible (`_triples`) and accelerate alike (within 1 px per frame² and
    `VOTE_ALIKE`).

    A clip faster than `VOTE_RATE` frames/s votes on every k-th frame (each of the k phases
    in turn), k making the votes' frames at most `VOTE_RATE` a second: at 240 frames/s a
    falling ball gains a tenth of a pixel of speed a frame, below what three positions show."""
    stride = _stride(t)
    votes, weights = [], []
    for phase in range(stride):
        v, w = _votes(cands[phase::stride], t[phase::stride], reach)
        votes += v
        weights += w
    if len(votes) < 3:
        return math.nan
    v, w = np.concatenate(votes), np.concatenate(weights)
    bins = np.arange(v.min() - 0.1, v.max() + 0.15, 0.05)
    hist, edges = np.histogram(v, bins=bins, weights=w)
    smooth = np.convolve(hist, [0.25, 0.5, 0.25], mode="same")
    k = int(np.argmax(smooth))
    near = np.abs(v - 0.5 * (edges[k] + edges[k + 1])) < 0.1
    return float(np.exp(np.average(v[near], weights=w[near])))


def _stride(t: np.ndarray) -> int:
    """Every how many frames a clip is looked at so as to see at most `VOTE_RATE` a second."""
    step = float(np.median(np.diff(t)))
    return max(1, int(math.ceil(1.0 / (VOTE_RATE * step) - 1e-9)))


def _votes(cands: list[_Candidates], t: np.ndarray, reach: float) -> tuple[list, list]:
    """The log vertical accelerations voted by the chains of five frames (`gravity_votes`),
    one list per voting chain start, and their weights (each start's votes share 1)."""
    n = len(cands)
    if n < 5:
        return [], []
    step = float(np.median(np.diff(t)))
    tri = [None] * n
    for i in range(1, n - 1):
        if len(cands[i - 1].pos) and len(cands[i].pos) and len(cands[i + 1].pos):
            dt1, dt2 = t[i] - t[i - 1], t[i + 1] - t[i]
            tri[i] = _triples(cands[i - 1], cands[i], cands[i + 1], dt1, dt2, step, reach)
    votes, weights = [], []
    for i in range(1, n - 3):
        if tri[i] is None or tri[i + 1] is None or tri[i + 2] is None:
            continue
        (a1, ok1), (a2, ok2), (a3, ok3) = tri[i], tri[i + 1], tri[i + 2]
        a1, a2, a3 = a1[:, :, :, None, None], a2[None, :, :, :, None], a3[None, None, :, :, :]
        mean = (a1 + a2 + a3) / 3.0
        tol = (1.0 + VOTE_ALIKE * mean[..., 1] * step**2) / step**2
        alike = (np.linalg.norm(a1 - mean, axis=-1) < tol) & (np.linalg.norm(a3 - mean, axis=-1) < tol)
        ok = alike & ok1[:, :, :, None, None] & ok2[None, :, :, :, None] & ok3[None, None, :, :, :]
        if ok.any():
            votes.append(np.log(mean[..., 1][ok]))
            weights.append(np.full(int(ok.sum()), 1.0 / ok.sum()))
    return votes, weights


# -- the path ---------------------------------------------------------------------------------


def _pad(cands: list[_Candidates], det: list[np.ndarray], m: int):
    """Positions (n, m+1, 2) and detection costs (n, m+1); slot m is 'none', unused slots inf."""
    n = len(cands)
    pos = np.full((n, m + 1, 2), np.nan)
    cost = np.full((n, m + 1), np.inf)
    for i, (c, d) in enumerate(zip(cands, det, strict=True)):
        k = len(c.pos)
        pos[i, :k] = c.pos
        cost[i, :k] = d
        cost[i, m] = MISSING_COST
    return pos, cost


def _motion_cost(p1, p2, p3, dt1, dt2, accel, step, known) -> np.ndarray:
    """The capped squared deviation of p3 from constant-acceleration motion through p1, p2
    (px; the tolerance grows with the speed: blur, drag, perspective; and with the fall
    over the step, by `VOTE_ALIKE` of it: the voted g is that uncertain, and a rolling
    shutter stretches a falling ball's steps and squeezes a rising one's); `GAP_COST` where a
    position is missing. Once the ball's looks are `known`, three positions at rest (held,
    resting) cost at most `REST_COST`, and a bounce at most `BOUNCE_COST`: a contact with
    the floor can only push the ball up, so three positions that span one end above the
    free-flight prediction (horizontally near it)."""
    fall = 0.5 * accel * dt2 * (dt1 + dt2)
    pred = p2 + (p2 - p1) * (dt2 / dt1) + fall
    miss = np.linalg.norm(p3 - pred, axis=-1)
    d1, d2 = np.linalg.norm(p2 - p1, axis=-1), np.linalg.norm(p3 - p2, axis=-1)
    tol = 1.0 + 0.08 * d1 * (step / dt1) + VOTE_ALIKE * float(np.linalg.norm(fall))
    cost = np.minimum((miss / tol) ** 2, MOTION_CAP)
    if known:
        rest = (d1 < REST_MOTION) & (d2 < REST_MOTION)
        cost = np.where(rest, np.minimum(cost, REST_COST), cost)
        pushed = (p3[..., 1] < pred[..., 1]) & (
            np.abs(p3[..., 0] - pred[..., 0]) < tol + 0.3 * np.maximum(d1, d2)
        )
        cost = np.where(pushed, np.minimum(cost, BOUNCE_COST), cost)
    return np.where(np.isnan(cost), GAP_COST, cost)


def _jump_cost(p1, p2, limit) -> np.ndarray:
    """MOTION_CAP for a step longer than `limit` px between two found positions, else 0."""
    d = np.linalg.norm(p2 - p1, axis=-1)
    return np.where(d > limit, MOTION_CAP, 0.0)


def choose_path(
    pos: np.ndarray, cost: np.ndarray, t: np.ndarray, gravity: float, limit: float, known: bool
) -> np.ndarray:
    """The candidate slot chosen in each frame (second-order Viterbi; slot m: none); `known`:
    whether the ball's looks are known (rest and bounces are then cheaper: `_motion_cost`)."""
    n, m1 = cost.shape
    accel = np.array([0.0, gravity])
    step = float(np.median(np.diff(t)))
    # D[j, k]: the best cost of a path whose last two slots are j (frame i-1), k (frame i)
    D = cost[0][:, None] + cost[1][None, :] + _jump_cost(pos[0][:, None], pos[1][None, :], limit)
    back = []
    for i in range(2, n):
        p1, p2, p3 = pos[i - 2][:, None, None], pos[i - 1][None, :, None], pos[i][None, None, :]
        trans = _motion_cost(p1, p2, p3, t[i - 1] - t[i - 2], t[i] - t[i - 1], accel, step, known)
        trans = trans + _jump_cost(p2, p3, limit)
        total = D[:, :, None] + trans  # (h, j, k)
        best = np.argmin(total, axis=0)  # (j, k)
        D = np.take_along_axis(total, best[None], axis=0)[0] + cost[i][None, :]
        back.append(best)
    j, k = np.unravel_index(np.argmin(D), D.shape)
    path = [k, j]
    for best in reversed(back):
        j, k = best[j, k], j
        path.append(j)
    return np.asarray(path[::-1])


def _appearance(cands: list[_Candidates], hint, size, colour) -> list[np.ndarray]:
    """Detection costs: shadow, and (when known) size and colour unlike the ball's (its hue,
    the hint's; its colour, the one learned in a first pass: `COLOUR_SCALE` gray levels
    cost 1)."""
    out = []
    for c in cands:
        cost = SHADOW_COST * c.shadow
        if size is not None:
            cost = cost + np.minimum((np.log(c.area / size) / 0.5) ** 2, APPEARANCE_CAP)
        if colour is not None and len(c.pos):
            dist = np.linalg.norm(c.colour - colour[None], axis=1) / COLOUR_SCALE
            cost = cost + np.minimum(dist**2, APPEARANCE_CAP)
        if hint is not None and len(c.pos):
            cost = cost + np.minimum((_angle(c.colour, hint[None]) / 12.0) ** 2, APPEARANCE_CAP)
        out.append(cost)
    return out


# -- the centre of the ball -------------------------------------------------------------------


def measure(frame, bg, labels, slot, colour, noise) -> tuple[float, float, float, float, float]:
    """Centre (x, y, working px), its uncertainty (px, per axis), diameter across the motion
    (px) and extent along it beyond the diameter (px) of candidate `slot` (0-based).

    The centre is the centroid of the ball's coverage around the blob (`coverage`), each
    pixel's coverage read against the ball's own shading near it (the largest coverage
    within `SHADING_REACH` px, at least `SHADING_FLOOR`: the shaded side of a ball reads
    less coverage than its lit side, and its edge pixels would weigh less) and saturated at
    `SATURATION` (a pixel the ball covers weighs 1 however brightly lit that part of the
    ball is; an edge pixel weighs its share); a highlight enclosed by the ball (no ball
    colour, a hole in the coverage) counts as covered. The extents are those of the
    half-covered pixels along the principal axes of that weight (a disc's extent is its
    diameter in every direction; motion blur stretches it along the motion only)."""
    mask = labels == slot + 1
    box = ndimage.find_objects(mask.astype(np.int8))[0]
    box = tuple(slice(max(0, b.start - 2), b.stop + 2) for b in box)
    region = ndimage.binary_dilation(mask[box], iterations=2)
    alpha_box, contrast_box = coverage(frame[box], bg[box], colour, noise)
    shade = ndimage.grey_dilation(alpha_box, size=(2 * SHADING_REACH + 1,) * 2)
    w_box = np.minimum(alpha_box / (np.maximum(shade, SHADING_FLOOR) * SATURATION), 1.0)
    w_box = np.clip((w_box - HALO) / (1.0 - HALO), 0.0, 1.0)
    holes = ndimage.binary_fill_holes(alpha_box >= 0.5) & (alpha_box < 0.5)
    w_box[holes] = 1.0
    yy, xx = np.nonzero(region)
    alpha, contrast, w = alpha_box[region], contrast_box[region], w_box[region]
    yy, xx = yy + box[0].start, xx + box[1].start
    total = w.sum()
    if total < 1.0:
        return (math.nan,) * 5
    x, y = float(np.sum(w * xx) / total), float(np.sum(w * yy) / total)
    dx, dy = xx - x, yy - y
    sig = np.where(w < 1.0, noise / (SATURATION * contrast), 0.0)
    var = np.sum(sig**2 * (dx**2 + dy**2)) / total**2
    cov = np.array([[np.sum(w * dx * dx), np.sum(w * dx * dy)], [np.sum(w * dx * dy), np.sum(w * dy * dy)]])
    _, axes = np.linalg.eigh(cov / total)
    half = alpha >= 0.5
    if half.sum() < 2:
        return x, y, float(math.sqrt(var / 2.0)), math.nan, math.nan
    across = dx[half] * axes[0, 0] + dy[half] * axes[1, 0]
    along = dx[half] * axes[0, 1] + dy[half] * axes[1, 1]
    width = float(np.ptp(across)) + 1.0
    return x, y, float(math.sqrt(var / 2.0)), width, max(0.0, float(np.ptp(along)) + 1.0 - width)


# -- the whole -------------------------------------------------------------------------------


def track(frames: Frames, *, colour=None, roi=None) -> Track:
    """Follow the ball through the unique frames of `frames` (see the module docstring).

    **Arguments:** `colour`: a hint (`parse_colour`: a name, '#rrggbb', r,g,b or a hue in
    degrees); `roi`: (x0, y0, x1, y1), source display px, the region searched.

    **Returns:** a `Track`. An `InputError` when no moving ball is found.
    """
    hint = parse_colour(colour)
    repeats = find_repeats(frames.t, frames.rgb)
    index = repeats.keep
    t, rgb = repeats.times, frames.rgb[index]
    bg = background(rgb)
    roi_mask = _roi_mask(roi, frames, bg.shape[:2])
    reach = 0.25 * math.hypot(*bg.shape[:2])
    # pass 1: blobs unlike the background; the ball's colour from the best path, on frames
    # at most VOTE_RATE a second (faster, gravity hardly moves the ball from frame to frame
    # and a still blob would fit as well as the falling ball)
    sub = slice(None, None, _stride(t))
    found = [candidates(f, bg, roi_mask) for f in rgb[sub]]
    path, gravity = _best_path(found, t[sub], reach, hint, None, None, frames.name)
    ball = _ball_colour(rgb[sub], found, path, hint)
    bg = background_without_ball(rgb[sub], found, path, bg)
    # pass 2: blobs that read as the ball's coverage (a shadow or a hand falls away)
    found = [candidates(f, bg, roi_mask, ball) for f in rgb]
    size = _ball_size(found, path=None)
    path, gravity = _best_path(found, t, reach, hint, size, ball, frames.name)
    out = np.full((len(t), 5), np.nan)
    for i, slot in enumerate(path):
        cands, labels, _, noise = found[i]
        if slot < len(cands.pos):
            out[i] = measure(rgb[i], bg, labels, slot, ball, noise)
    return _to_source(frames, repeats, index, t, out, gravity, ball, roi, hint)


def _best_path(found, t, reach, hint, size, colour, name) -> tuple[np.ndarray, float]:
    """The chosen slot per frame (`choose_path`) and g in working px/s² (`gravity_votes`)."""
    cands = [c for c, _, _, _ in found]
    gravity = gravity_votes(cands, t, reach)
    if not math.isfinite(gravity):
        raise InputError(
            f"{name}: no object moves like a falling ball in the {len(t)} unique frames (is the ball in "
            "view and in motion? is the picture upside down or sideways, its rotation metadata wrong? "
            "give the ball's colour or a region: color, roi)"
        )
    m = max(1, max(len(c.pos) for c in cands))
    pos, cost = _pad(cands, _appearance(cands, hint, size, colour), m)
    return choose_path(pos, cost, t, gravity, reach, size is not None), gravity


def _ball_size(found, path) -> float | None:
    """The median area (working px) of the blobs on `path`, or (path None) of the blobs that
    the coverage finds, weighted by their contrast mass."""
    if path is None:
        areas = np.concatenate([c.area for c, _, _, _ in found])
        masses = np.concatenate([c.mass for c, _, _, _ in found])
        if not len(areas):
            return None
        order = np.argsort(areas)
        cum = np.cumsum(masses[order])
        return float(areas[order][np.searchsorted(cum, 0.5 * cum[-1])])
    chosen = [c.area[s] for (c, _, _, _), s in zip(found, path, strict=True) if s < len(c.pos)]
    return float(np.median(chosen)) if chosen else None


def _ball_colour(rgb, found, path, hint) -> np.ndarray:
    """The ball's colour: the median over the chosen blobs of their core colour (the hint if none)."""
    cols = [c.colour[s] for (c, _, _, _), s in zip(found, path, strict=True) if s < len(c.pos)]
    if cols:
        return np.median(cols, axis=0)
    if hint is not None:
        return np.asarray(hint, dtype=float)
    return np.full(3, 255.0)


def _to_source(frames, repeats, index, t, out, gravity, colour, roi, hint) -> Track:
    """The `Track` in source display pixels."""
    fx, fy = frames.factor
    x, y = frames.to_source(out[:, 0], out[:, 1])
    scale = math.sqrt(fx * fy)
    notes = [
        f"tracked: the ball found in {int(np.isfinite(out[:, 1]).sum())} of {len(t)} unique frames "
        f"(median background, colour {'hint' if hint is not None else 'learned'} "
        f"rgb({colour[0]:.0f}, {colour[1]:.0f}, {colour[2]:.0f}))"
    ]
    return Track(
        frames=frames,
        repeats=repeats,
        index=index,
        t=t,
        x=np.asarray(x, dtype=float),
        y=np.asarray(y, dtype=float),
        sigma=out[:, 2] * scale,
        diameter=out[:, 3] * scale,
        blur=out[:, 4] * scale,
        gravity_px=gravity * fy,
        colour=tuple(float(c) for c in colour),
        roi=None if roi is None else tuple(float(v) for v in roi),
        notes=tuple(notes),
    )
