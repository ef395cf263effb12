"""From music beats to the beat grid an engine dances on, and the style that suits it.

The grid is the music's beats, extended with beats at the local beat period before
the first and after the last detected beat so that the whole song -- from 0 s to
its end -- is covered by beat intervals (the dancer never stands still waiting for
the first beat).

The grid has a *metrical level*, ``subdivide`` grid beats per music beat:

- ``1``: on the beat;
- an integer ``n > 1``: each interval split ``n`` times (``2`` is double time, for a
  song much slower than every style); every music beat stays a grid beat;
- ``1 / n``: every ``n``-th music beat is a grid beat (``0.5`` is half time, for a song
  much faster than a style); the kept beats are the ones the downbeats fall on;
- sections ``((0, 2), (96, 1))``: the level changes at those music beats (a mix whose
  tempo changes: double time for its slow part, the beat for its fast part).

A beat piece -- a captured motion-beat interval played over one grid interval -- is
time-warped to fit; played faster or slower than ``RATE_RANGE`` it looks sped up or
in slow motion. ``fit_style`` therefore picks the style and level from the share of
pieces expected within that range: the style's captured motion-beat intervals
against the grid intervals, beat by beat, following the song's tempo curve.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..motion.database import MotionDatabase, Style
from ..types import FALLBACK_BPM, MusicFeatures
from ..errors import InputError

RATE_RANGE = (0.8, 1.25)   # playback rates (captured seconds per music second) that still look natural
TARGET_SHARE = 0.9         # below this expected share of pieces in RATE_RANGE, the summary warns
LEVELS = (1, 2, 0.5)       # the metrical levels fit_style tries: the beat, double time, half time
NEAR_SHARE = 0.05          # fits within this share of the best are equally good: prefer the beat, a big style
METRE_SHARE = 0.5          # a song in three may take a style that fits its tempo less well, down to this share,
                           # if that style dances in three (whirl, 81 bpm, on a 100 bpm waltz: 0.55 expected)
MIN_MATERIAL_MINUTES = 2.0  # a style with less captured motion at a song's tempo (minutes x expected share) loops
                           # visibly: it is chosen only when named, or when no style has more
MIN_SECTION_BEATS = 32     # a section with its own level lasts at least this many music beats (8 bars of 4)
LOCAL_TEMPO_BEATS = 8      # the local beat period is the median over this many beats on either side


def level_name(subdivide) -> str:
    """"beat", "double time", "half time", "3 per beat", "1 per 3 beats" or, for sections, "A, then B"."""
    if not np.isscalar(subdivide):
        return ", then ".join(level_name(s) for _, s in subdivide)
    named = {1: "beat", 2: "double time", 0.5: "half time"}
    if subdivide in named:
        return named[subdivide]
    return f"{subdivide:g} per beat" if subdivide > 1 else f"1 per {round(1 / subdivide)} beats"


def _merge(subdivide: float) -> int:
    """Music beats per grid beat (1 unless ``subdivide`` is ``1/n``)."""
    return int(round(1.0 / subdivide)) if subdivide < 1 else 1


def _sections(subdivide, n_beats: int) -> list[tuple[int, float]]:
    """``subdivide`` as a checked list of (first music beat, level), the first at beat 0."""
    plan = [(0, subdivide)] if np.isscalar(subdivide) else [(int(b), s) for b, s in subdivide]
    if not plan or plan[0][0] != 0 or any(b1 <= b0 for (b0, _), (b1, _) in zip(plan, plan[1:])) \
            or plan[-1][0] >= n_beats - 1:
        raise InputError(f"sections {subdivide!r} must start at music beat 0 and increase within the song")
    for _, s in plan:
        ok = (s >= 1 and float(s).is_integer()) or (0 < s < 1 and abs(1.0 / s - round(1.0 / s)) < 1e-6)
        if not ok:
            raise InputError(f"subdivide {s!r} must be a whole number >= 1 or 1/n (0.5 is half time)")
    return plan


@dataclass(frozen=True)
class BeatGrid:
    times_s: np.ndarray         # (G,) increasing; times_s[0] <= 0 and times_s[-1] >= duration
    intensity_db: np.ndarray    # (G-1,) per interval
    is_music_beat: np.ndarray   # (G,) bool: this grid beat is a detected music beat
    subdivide: float | tuple = 1  # grid beats per music beat, or sections ((first music beat, level), ...)
    count: np.ndarray | None = None  # (G,) music beats counted at each grid beat (fractions between beats)
    bar_position: np.ndarray | None = None  # (G,) position in the bar (0 = downbeat; -1: no music beat or
    beats_per_bar: int | None = None        # the metre unknown) and the bar's length

    @property
    def n_intervals(self) -> int:
        return len(self.times_s) - 1


def _half_phase(music: MusicFeatures, merge: int) -> int:
    """Which music beats (index mod ``merge``) stay grid beats at 1 per ``merge`` beats: the downbeats'."""
    bars = music.beat_in_bar
    if bars is None or merge < 2:
        return 0
    down = np.flatnonzero(np.asarray(bars) == 0)
    return int(np.bincount(down % merge, minlength=merge).argmax()) if down.size else 0


def beat_grid(music: MusicFeatures, *, subdivide=1) -> BeatGrid:
    """The beat grid of ``music`` covering [0, duration] at the metrical level ``subdivide``.

    ``subdivide`` is grid beats per music beat: a whole number (each interval split that
    many times), ``1/n`` (every n-th music beat, the downbeats among them) or sections
    ``((first_music_beat, level), ...)`` starting at beat 0 (see the module's notes).
    """
    beats = np.asarray(music.beat_times_s, dtype=np.float64)
    inten = np.asarray(music.intensity_db, dtype=np.float64)
    if beats.size < 2:
        raise InputError("beat_grid needs at least two beats")
    plan = _sections(subdivide, beats.size)
    # A merged level at either end takes margin beats beyond the song, so that whichever
    # music beats it keeps, a kept beat still lies at or before 0 s and at or after the end.
    margin_before, margin_after = _merge(plan[0][1]) - 1, _merge(plan[-1][1]) - 1
    first_period = float(beats[1] - beats[0])
    last_period = float(beats[-1] - beats[-2])
    n_before = int(np.ceil(max(beats[0], 0.0) / first_period - 1e-9)) + margin_before
    n_after = int(np.ceil(max(music.duration_s - beats[-1], 0.0) / last_period - 1e-9)) + margin_after
    times = np.concatenate([beats[0] - first_period * np.arange(n_before, 0, -1), beats,
                            beats[-1] + last_period * np.arange(1, n_after + 1)])
    intensity = np.concatenate([np.full(n_before, inten[0]), inten, np.full(n_after, inten[-1])])
    is_beat = np.zeros(len(times), dtype=bool)
    is_beat[n_before:n_before + beats.size] = True
    extended = times
    if len(plan) == 1 and plan[0][1] >= 1:  # one level, each interval split: the plain case
        sub = int(plan[0][1])
        if sub > 1:
            frac = np.arange(sub) / sub
            split = (times[:-1, None] + np.diff(times)[:, None] * frac[None, :]).ravel()
            times = np.r_[split, times[-1]]
            intensity = np.repeat(intensity, sub)
            is_beat = np.r_[(is_beat[:-1, None] & (frac == 0)[None, :]).ravel(), is_beat[-1:]]
        return BeatGrid(times, intensity, is_beat, plan[0][1], _counts(times, extended),
                        *_bar_positions(times, music))

    # Sections, or a merged level: build each section from the extended beats it covers.
    starts = [0] + [n_before + b for b, _ in plan[1:]]
    ends = starts[1:] + [len(times) - 1]
    cum = np.r_[0.0, np.cumsum(intensity)]
    out_t, out_i, out_b = [], [], []
    for k, ((_, level), s, e) in enumerate(zip(plan, starts, ends)):
        merge = _merge(level)
        if merge > 1:
            first = s + (n_before + _half_phase(music, merge) - s) % merge if k == 0 else s
            idx = np.arange(first, e, merge)
            nxt = np.r_[idx[1:], e]
            out_t.append(times[idx])
            out_b.append(is_beat[idx])
            out_i.append((cum[nxt] - cum[idx]) / (nxt - idx))  # the merged intervals' mean loudness
        else:
            sub = int(level)
            frac = np.arange(sub) / sub
            t0, d = times[s:e], np.diff(times[s:e + 1])
            out_t.append((t0[:, None] + d[:, None] * frac[None, :]).ravel())
            out_b.append((is_beat[s:e, None] & (frac == 0)[None, :]).ravel())
            out_i.append(np.repeat(intensity[s:e], sub))
    times = np.r_[np.concatenate(out_t), times[-1]]
    is_beat = np.r_[np.concatenate(out_b), is_beat[-1]]
    intensity = np.concatenate(out_i)
    # Drop the margin's grid beats that a covering beat makes unnecessary.
    a = max(int(np.searchsorted(times, 0.0, side="right")) - 1, 0) if margin_before else 0
    b = min(int(np.searchsorted(times, music.duration_s, side="left")), len(times) - 1) if margin_after \
        else len(times) - 1
    spec = plan[0][1] if len(plan) == 1 else tuple(plan)
    times = times[a:b + 1]
    return BeatGrid(times, intensity[a:b], is_beat[a:b + 1], spec, _counts(times, extended),
                    *_bar_positions(times, music))


def _bar_positions(grid_s: np.ndarray, music: MusicFeatures) -> tuple[np.ndarray, int | None]:
    """Each grid beat's position in its bar (-1 where it is no music beat or the metre is unknown)."""
    out = np.full(len(grid_s), -1, dtype=np.int64)
    if music.beat_in_bar is None:
        return out, None
    beats = music.beat_times_s
    i = np.clip(np.searchsorted(beats, grid_s), 0, len(beats) - 1)
    for j in (i, np.maximum(i - 1, 0)):  # the grid holds the music's beats as they are, give or take rounding
        hit = np.abs(beats[j] - grid_s) < 1e-6
        out[hit] = music.beat_in_bar[j[hit]]
    return out, music.beats_per_bar


def _counts(grid_s: np.ndarray, beats_s: np.ndarray) -> np.ndarray:
    """Music beats counted at each grid time: ``beats_s`` (every music beat, the song's own
    and those carried on before and after it) count 0, 1, 2, ...; times between them count
    the fraction of the beat gone by."""
    return np.interp(grid_s, beats_s, np.arange(len(beats_s), dtype=np.float64))


# ---------------------------------------------------------------------------------------------
# Choosing the style and the metrical level


def motion_intervals_s(style: Style) -> np.ndarray:
    """The style's captured motion-beat intervals in seconds, sorted (intervals across clips left out)."""
    frames = np.asarray(style.beat_frames)
    if frames.size < 2:
        return np.zeros(0)
    clip = np.searchsorted(np.asarray(style.clip_starts), frames, side="right") - 1
    same = clip[1:] == clip[:-1]
    return np.sort(np.diff(frames)[same] / float(style.fps))


def in_range_shares(motion_s: np.ndarray, grid_s: np.ndarray, rates=RATE_RANGE) -> np.ndarray:
    """Per grid interval: the share of the (sorted) motion intervals that would play at a rate in ``rates``."""
    grid_s = np.asarray(grid_s, dtype=np.float64)
    if motion_s.size == 0:
        return np.zeros(grid_s.shape)
    lo = np.searchsorted(motion_s, rates[0] * grid_s - 1e-9, side="left")
    hi = np.searchsorted(motion_s, rates[1] * grid_s + 1e-9, side="right")
    return (hi - lo) / motion_s.size


def grid_intervals_s(beat_intervals_s: np.ndarray, subdivide) -> np.ndarray:
    """The grid intervals a level makes of the music's beat intervals (sections: each at its own)."""
    ib = np.asarray(beat_intervals_s, dtype=np.float64)
    if not np.isscalar(subdivide):
        bounds = [b for b, _ in subdivide] + [len(ib)]
        return np.concatenate([grid_intervals_s(ib[b0:b1], s)
                               for (b0, s), b1 in zip(subdivide, bounds[1:])])
    merge = _merge(subdivide)
    if merge > 1:  # both phases: which beats are kept is decided later, by the downbeats
        return np.convolve(ib, np.ones(merge), mode="valid") if ib.size >= merge else ib.sum(keepdims=True)
    return np.repeat(ib / subdivide, int(subdivide))


@dataclass(frozen=True)
class StyleFit:
    """A style and the metrical level to dance it at, with the warp it is expected to need."""

    style: Style
    subdivide: float | tuple   # as beat_grid takes it
    share: float               # expected share of beat pieces played at a rate within RATE_RANGE
    rate: float                # typical playback rate (median captured interval / median grid interval)
    forced: bool = False       # the user named this style (or its genre)
    for_metre: bool = False    # a worse fit to the tempo, tried because the best fits do not dance in three

    @property
    def level(self) -> str:
        return level_name(self.subdivide)

    @property
    def material_minutes(self) -> float:
        """Captured minutes the song can be danced with at this level: the style's captured minutes times
        the expected share of its beat pieces within ``RATE_RANGE`` (its mirrored takes not counted)."""
        return self.style.captured_s / 60.0 * self.share


def _fit(style: Style, motion_s: np.ndarray, beat_intervals_s: np.ndarray, subdivide, forced: bool) -> StyleFit:
    grid_s = grid_intervals_s(beat_intervals_s, subdivide)
    share = float(np.mean(in_range_shares(motion_s, grid_s))) if grid_s.size else 0.0
    rate = float(np.median(motion_s) / np.median(grid_s)) if motion_s.size and grid_s.size else float("nan")
    return StyleFit(style, subdivide, share, rate, forced)


def _local_period(beat_intervals_s: np.ndarray) -> np.ndarray:
    """Per music beat interval: the median interval over ``LOCAL_TEMPO_BEATS`` beats on either side."""
    ib = np.asarray(beat_intervals_s, dtype=np.float64)
    w = LOCAL_TEMPO_BEATS
    padded = np.pad(ib, w, mode="edge")
    return np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * w + 1), axis=1)


def section_levels(motion_s: np.ndarray, beat_intervals_s: np.ndarray, beat_in_bar=None, *,
                   levels=LEVELS, min_beats: int = MIN_SECTION_BEATS):
    """Sections ``((first_music_beat, level), ...)`` following a changing tempo, or one level.

    Each music beat interval takes the level whose grid interval at the local beat period
    fits most motion intervals (the beat preferred on near ties); runs shorter than
    ``min_beats`` join a neighbour; boundaries move to the nearest downbeat, and a merged
    level's section keeps an even number of beats so its grid beats pair up.
    """
    ib = np.asarray(beat_intervals_s, dtype=np.float64)
    n = ib.size
    if n < 2 * min_beats:
        return None
    period = _local_period(ib)
    levels = list(levels)
    score = np.stack([in_range_shares(motion_s, period / lv) + (NEAR_SHARE if lv == 1 else 0.0) for lv in levels])
    label = score.argmax(axis=0)
    runs = [[int(b), int(label[b])] for b in np.flatnonzero(np.r_[True, label[1:] != label[:-1]])]
    while len(runs) > 1:
        length = np.diff([r[0] for r in runs] + [n])
        k = int(length.argmin())
        if length[k] >= min_beats:
            break
        # The short run joins the neighbour whose level fits it better.
        a, b = runs[k][0], runs[k][0] + length[k]
        left = runs[k - 1][1] if k > 0 else None
        right = runs[k + 1][1] if k + 1 < len(runs) else None
        pick = max((x for x in (left, right) if x is not None), key=lambda lv: score[lv, a:b].sum())
        runs[k][1] = pick
        merged = [runs[0]]
        for r in runs[1:]:
            if r[1] != merged[-1][1]:
                merged.append(r)
        runs = merged
    if len(runs) == 1:
        return None
    if beat_in_bar is not None:  # sections start on a downbeat where there is one near
        down = np.flatnonzero(np.asarray(beat_in_bar)[:n] == 0)
        if down.size:
            for r in runs[1:]:
                r[0] = int(down[np.abs(down - r[0]).argmin()])
    plan = []
    for b, lab in runs:
        if plan and b <= plan[-1][0]:
            continue
        lv = levels[lab]
        if plan and _merge(plan[-1][1]) > 1 and (b - plan[-1][0]) % _merge(plan[-1][1]):
            b += _merge(plan[-1][1]) - (b - plan[-1][0]) % _merge(plan[-1][1])
        if b >= n - 1:
            break
        if plan and lv == plan[-1][1]:
            continue
        plan.append((b, lv))
    return tuple(plan) if len(plan) > 1 else None


def style_fits(db: MotionDatabase, beat_intervals_s, name: str | None = None, *, levels=LEVELS,
               beat_in_bar=None, sections: bool = True, prefer: tuple[str, ...] = ()) -> list[StyleFit]:
    """Every candidate (style, level) with its expected in-range share, the best first.

    Candidates are the styles called ``name`` (or of genre ``name``), or all styles, each
    at every level of ``levels`` and -- with ``sections`` -- at levels that change with
    the song's tempo. The best fit has the highest share; fits within ``NEAR_SHARE`` of
    it (and reaching ``TARGET_SHARE`` if the best does) count as equally good and go to a
    single level, the beat, the most material at the song's tempo, and the rate nearest 1, in that order.

    Unless ``name`` is given, a fit with less than ``MIN_MATERIAL_MINUTES`` of material at the
    song's tempo (``StyleFit.material_minutes``) comes after every fit with more, and a style
    with less than that in all comes last: a 30-second style would loop one clip over a song.
    Among the fits as good as the best, styles of a genre in ``prefer`` (the song's genre tag,
    ``genre_preference``) go first.
    """
    ib = np.asarray(beat_intervals_s, dtype=np.float64)
    ib = ib[np.isfinite(ib) & (ib > 0)]
    if ib.size == 0:
        raise InputError("style_fits needs at least one beat interval")
    candidates = db.styles_of(name) if name else list(db.styles.values())
    fits = []
    for st in candidates:
        motion = motion_intervals_s(st)
        fits += [_fit(st, motion, ib, lv, name is not None) for lv in levels]
        plan = section_levels(motion, ib, beat_in_bar, levels=levels) if sections else None
        if plan is not None:
            fits.append(_fit(st, motion, ib, plan, name is not None))
    tier = {id(f): 0 if name else material_tier(f) for f in fits}
    first = min(tier.values())
    best = max(f.share for f in fits if tier[id(f)] == first)

    def key(f: StyleFit):
        rate = abs(np.log(f.rate)) if np.isfinite(f.rate) and f.rate > 0 else np.inf
        return (tier[id(f)], not _near(f, best), f.style.genre not in prefer, not np.isscalar(f.subdivide),
                f.subdivide != 1, -f.material_minutes, rate, -f.share)

    return sorted(fits, key=key)


def material_tier(fit: StyleFit) -> int:
    """0: enough material at the song's tempo; 1: a big enough style, but little of it fits the tempo;
    2: a style smaller than ``MIN_MATERIAL_MINUTES`` altogether."""
    if fit.style.captured_s / 60.0 < MIN_MATERIAL_MINUTES:
        return 2
    return 0 if fit.material_minutes >= MIN_MATERIAL_MINUTES else 1


def _near(fit: StyleFit, best: float) -> bool:
    """Near the best share -- but never a fit that misses the target when another reaches it."""
    return fit.share >= best - NEAR_SHARE and (fit.share >= TARGET_SHARE or best < TARGET_SHARE)


def equally_good(fits: list[StyleFit]) -> list[StyleFit]:
    """Of ``style_fits``' list, the fits as good as the first, the first of each style, in order."""
    forced = fits[0].forced
    tier = material_tier(fits[0])
    same = [f for f in fits if forced or material_tier(f) == tier]
    best = max(f.share for f in same)
    out, seen = [], set()
    for f in same:
        if _near(f, best) and f.style.name not in seen:
            seen.add(f.style.name)
            out.append(f)
    return out


def fit_style(db: MotionDatabase, music: MusicFeatures, name: str | None = None, *, levels=LEVELS,
              sections: bool = True) -> StyleFit:
    """The style (among ``name``'s, or all) and metrical level that warp ``music``'s beat pieces least."""
    return fit_styles(db, music, name, levels=levels, sections=sections)[0]


def fit_styles(db: MotionDatabase, music: MusicFeatures, name: str | None = None, *, levels=LEVELS,
               sections: bool = True, min_share: float | None = None, prefer: tuple[str, ...] = ()) -> list[StyleFit]:
    """``fit_style`` and then the other styles that fit as well (``equally_good``), in order; with
    ``min_share``, then each remaining style's best fit that reaches it, the best first."""
    fits = style_fits(db, np.diff(music.beat_times_s), name, levels=levels, beat_in_bar=music.beat_in_bar,
                      sections=sections, prefer=prefer)
    out = equally_good(fits)
    if min_share is not None:
        seen = {f.style.name for f in out}
        for f in sorted(fits, key=lambda f: -f.share):
            if f.share >= min_share and f.style.name not in seen and (f.forced or material_tier(f) == 0):
                seen.add(f.style.name)
                out.append(replace(f, for_metre=True))
    return out


def choose_style(db: MotionDatabase, tempo_bpm: float, name: str | None = None, *,
                 levels=(1, 2)) -> tuple[Style, float]:
    """The style and subdivision for a steady ``tempo_bpm`` (``fit_style`` for one tempo).

    Only the beat and double time by default: callers that cannot dance half time (the
    live runtime dances the beat it hears) keep getting a style that fits the beat.
    """
    period = 60.0 / (tempo_bpm if tempo_bpm > 0 else FALLBACK_BPM)
    fit = style_fits(db, np.full(64, period), name, levels=levels, sections=False)[0]
    return fit.style, fit.subdivide


def tempo_map(db: MotionDatabase, tempi_bpm, *, levels=LEVELS) -> list[dict]:
    """For each steady tempo: every (style, level) with at least ``MIN_MATERIAL_MINUTES`` of material
    there (``StyleFit.material_minutes``: captured minutes within ``RATE_RANGE`` of their speed), the
    most first, and the style ``style_fits`` would choose."""
    rows = []
    for bpm in tempi_bpm:
        fits = style_fits(db, np.full(64, 60.0 / float(bpm)), levels=levels, sections=False)
        usable = sorted((f for f in fits if f.material_minutes >= MIN_MATERIAL_MINUTES),
                        key=lambda f: -f.material_minutes)
        rows.append({"tempo_bpm": float(bpm), "chosen": fits[0].style.name, "chosen_level": fits[0].level,
                     "chosen_minutes": fits[0].material_minutes,
                     "styles": [{"style": f.style.name, "level": f.level, "minutes": f.material_minutes,
                                 "share": f.share, "mirrored": f.style.mirror} for f in usable]})
    return rows


# The bundled genres each tag family (``music.tags.genre_families``) may be danced as; a database's
# genre named like a family (a user's "hiphop" folder) matches it as well.
FAMILY_GENRES = {"pop": ("pop",), "hiphop": ("pop", "mj"), "salsa": ("salsa",),
                 "indian": ("indian",), "jazz": ("pop",)}


def genre_preference(db: MotionDatabase, tag: str | None) -> tuple[str, ...]:
    """The database's genres a song's genre ``tag`` suggests, most specific first (none: ())."""
    from ..music.tags import genre_families

    if not tag:
        return ()
    genres = set(db.genres())
    out: list[str] = []
    for family in genre_families(tag):
        for g in (family,) + FAMILY_GENRES.get(family, ()):
            if g in genres and g not in out:
                out.append(g)
    return tuple(out)


def fit_summary(fit: StyleFit, music: MusicFeatures, warp_rates=None) -> dict:
    """The summary's account of the warp: level, sections, expected and actual in-range share, warnings.

    ``warp_rates`` are the danced beat pieces' playback rates (None where the engine has none).
    """
    plan = _sections(fit.subdivide, len(music.beat_times_s))
    beats = np.asarray(music.beat_times_s)
    actual = None
    if warp_rates is not None and len(warp_rates):
        r = np.asarray(warp_rates, dtype=np.float64)
        actual = float(np.mean((r >= RATE_RANGE[0]) & (r <= RATE_RANGE[1])))
    return {"level": fit.level, "rate_range": list(RATE_RANGE),
            "sections": [{"start_s": 0.0 if k == 0 else float(beats[b]), "level": level_name(s), "subdivide": s}
                         for k, (b, s) in enumerate(plan)],
            "in_range_expected": fit.share, "in_range_actual": actual, "typical_rate": fit.rate,
            "warnings": fit_warnings(fit, music.tempo_bpm, actual)}


def fit_warnings(fit: StyleFit, tempo_bpm: float, actual: float | None = None) -> list[str]:
    """What a user should know about the warp: a style that fits the music poorly."""
    if fit.share >= TARGET_SHARE:
        return []
    st = fit.style
    how = ("slowed down" if fit.rate < RATE_RANGE[0] else "sped up" if fit.rate > RATE_RANGE[1]
           else "unevenly sped up and slowed down")
    lo, hi = RATE_RANGE
    at = "on the beat" if fit.subdivide == 1 else f"at {fit.level}"
    done = f" ({actual:.0%} were)" if actual is not None else ""
    what = (f"{at}, its beat pieces play at typically {fit.rate:.2f}x their captured speed and only "
            f"{fit.share:.0%} are expected within {lo:g}-{hi:g}x{done}, so the dance will look {how}")
    if fit.for_metre:
        return [f"style '{st.name}' (captured at about {st.natural_tempo_bpm:.0f} bpm) dances this {tempo_bpm:.0f} "
                f"bpm music in three, which the styles that fit its tempo better do not: {what}"]
    if fit.forced:
        return [f"style '{st.name}' (captured at about {st.natural_tempo_bpm:.0f} bpm) fits this "
                f"{tempo_bpm:.0f} bpm music poorly: {what}; leave out --style, or pick a style captured near "
                f"{tempo_bpm:.0f} bpm ('dancesynth styles')"]
    return [f"no style of the database fits this {tempo_bpm:.0f} bpm music well: the best, '{st.name}' "
            f"(captured at about {st.natural_tempo_bpm:.0f} bpm), {what}"]
