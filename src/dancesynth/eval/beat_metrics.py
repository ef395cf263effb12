"""Metrics on plain arrays: beat times, per-beat values, histograms and time-warp rates.

Every function here is pure (no files, no printing) and follows mir_eval's shape:
``metric(reference, estimated, *, named_params) -> float``. Times and tolerances
are in seconds, never frames. Bad input (NaN, a matrix where a list of times was
expected, a negative tolerance, histograms of different lengths) raises
``dancesynth.errors.InputError`` with a message that says how to fix it.

Undefined-but-valid input has one rule throughout:

- a mean over an empty set is undefined and returns ``float('nan')`` (no motion
  beats to average over, no music beats to count, fewer than 3 intervals to rank);
- a distance to an empty set is +infinity (no music beat near any motion beat), so
  scores built on it are 0.0.

``dancesynth.eval.evaluate`` turns NaN into ``None`` ("not applicable").
Metrics computed from a ``MotionClip`` live in ``motion_metrics``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..errors import InputError

#: Two times closer than this count as equal (1 ns): a beat exactly one window away
#: from another is inside the window despite the rounding of ``a - b``.
TIME_TOL_S = 1e-9

#: Defaults shared with ``evaluate.EvalParams`` (one source).
DEFAULT_SIGMA_S = 0.05          # FACT/Bailando: sigma^2 = 9 frames^2 at 60 fps = (50 ms)^2
DEFAULT_HIT_WINDOW_S = 0.05
DEFAULT_BEAT_WINDOW_S = 0.07    # mir_eval.beat.f_measure's default
DEFAULT_SKIP_S = 5.0            # mir_eval.beat.trim_beats's default

_NAN = float("nan")
_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


# ---------------------------------------------------------------------------------------------
# Validation


def as_times(x, name: str, *, sort: bool = True) -> np.ndarray:
    """``x`` as a 1-D float array of finite times in seconds (sorted unless ``sort=False``).

    The metrics do not care about the order of the input; an empty list is valid.
    Anything else raises ``InputError``.
    """
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a list or 1-D array of times in seconds, "
                         f"got {type(x).__name__} ({exc})") from exc
    if a.ndim != 1:
        what = "a single number" if a.ndim == 0 else f"an array of shape {a.shape}"
        raise InputError(f"{name} must be a 1-D array of times in seconds, got {what}; "
                         "pass a list such as [0.5, 1.0, 1.5]")
    _finite(a, name, "times must be finite seconds; drop the missing ones")
    return np.sort(a) if sort else a


def as_values(x, name: str, *, allow_inf: bool = False) -> np.ndarray:
    """``x`` as a 1-D float array without NaN (order kept), or ``InputError``."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a list or 1-D array of numbers, got {type(x).__name__} ({exc})") from exc
    if a.ndim != 1:
        raise InputError(f"{name} must be a 1-D array of numbers, got shape {a.shape}; flatten it")
    if allow_inf:
        bad = np.isnan(a)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{name} has NaN at index {i}; drop that value (and its partner) or fill it in")
    else:
        _finite(a, name, "drop or fill in the missing values")
    return a


def _finite(a: np.ndarray, name: str, hint: str) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"{name} has a non-finite value ({a.flat[i]}) at index {i}; {hint}")


def check_seconds(value, name: str, *, allow_zero: bool = False) -> float:
    """A positive (or, with ``allow_zero``, non-negative) finite number of seconds."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number of seconds, got {value!r}") from exc
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        need = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} must be a {need} number of seconds (e.g. 0.05), got {value!r}")
    return v


def _nearest_distance(points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """For each point, the distance to the nearest target (+inf when there are none)."""
    if targets.size == 0:
        return np.full(points.shape, np.inf)
    i = np.searchsorted(targets, points)
    lo = targets[np.clip(i - 1, 0, targets.size - 1)]
    hi = targets[np.clip(i, 0, targets.size - 1)]
    return np.minimum(np.abs(points - lo), np.abs(points - hi))


# ---------------------------------------------------------------------------------------------
# Beat alignment of a dance with its music


def beat_align_score(music_beats_s, motion_beats_s, *, sigma_s: float = DEFAULT_SIGMA_S,
                     average_over: str = "motion") -> float:
    """Beat Align Score (BAS): how close beats of one kind lie to beats of the other.

    ``average_over="motion"`` (the AI Choreographer / FACT code, Li et al. 2021,
    ``mint/tools/calculate_beat_scores.py``: ``alignment_score``)::

        BAS = 1/|M| * sum_{m in motion beats} exp(-min_a (m - a)^2 / (2 sigma^2))

    with ``a`` over the music beats. ``average_over="music"`` (Bailando's code,
    Siyao et al. 2022, ``utils/metrics_new.py``: ``BA``) swaps the roles: the mean
    over *music* beats of the Gaussian of the distance to the nearest *motion* beat.

    The two directions answer different questions. Averaged over motion beats, a
    dance scores high when every movement accent falls on a beat, however many beats
    it skips; averaged over music beats, it scores high when every beat is marked by
    some accent, however many off-beat accents it adds. Papers report either under
    the same name; say which one you quote.

    ``sigma_s`` is in seconds. The original codes state sigma in motion frames:
    FACT uses sigma = 3 frames at 60 fps and Bailando sigma^2 = 9 frames^2 at 60 fps,
    both 50 ms -- our default. (Code running at another frame rate with the same
    frame sigma measures something else.)

    Returns a value in [0, 1]; NaN when the beats averaged over are empty; 0.0 when
    only the other list is empty (every distance is infinite). FACT returns 0.0 when
    there are no motion beats; we return NaN because a mean over nothing is undefined.
    """
    music = as_times(music_beats_s, "music_beats_s")
    motion = as_times(motion_beats_s, "motion_beats_s")
    sigma = check_seconds(sigma_s, "sigma_s")
    if average_over == "motion":
        points, targets = motion, music
    elif average_over == "music":
        points, targets = music, motion
    else:
        raise InputError(f"average_over must be 'motion' (FACT/AIST++) or 'music' (Bailando), got {average_over!r}")
    if points.size == 0:
        return _NAN
    d = _nearest_distance(points, targets)
    return float(np.mean(np.exp(-d * d / (2.0 * sigma * sigma))))


def hit_rate(music_beats_s, motion_beats_s, *, window_s: float = DEFAULT_HIT_WINDOW_S) -> float:
    """Fraction of music beats that have a motion beat within +-``window_s``.

    ``hit = |{a in music : min_m |a - m| <= window_s}| / |music|`` (a motion beat may
    serve several music beats). Distances within 1 ns of the window count as inside.
    NaN when there are no music beats; 0.0 when there are no motion beats.
    This is the music-side count: Lee et al. 2019 (Dancing to Music) call "beat hit
    rate" the kinematic-side count, which is ``aligned_beat_ratio`` here.
    """
    music = as_times(music_beats_s, "music_beats_s")
    motion = as_times(motion_beats_s, "motion_beats_s")
    window = check_seconds(window_s, "window_s", allow_zero=True)
    if music.size == 0:
        return _NAN
    return float(np.mean(_nearest_distance(music, motion) <= window + TIME_TOL_S))


def beat_count_ratio(music_beats_s, motion_beats_s) -> float:
    """Number of kinematic (motion) beats divided by the number of music beats.

    Aristidou et al., Rhythm is a Dancer, §5.4.1, measure (a): they report 25.2 % for
    their mocap and 24.4 % for their dances, so compare the value with the mocap's,
    not with 1 (it shows whether the dance moves at the mocap's pace).
    NaN when there are no music beats.
    """
    music = as_times(music_beats_s, "music_beats_s")
    motion = as_times(motion_beats_s, "motion_beats_s")
    if music.size == 0:
        return _NAN
    return float(motion.size / music.size)


def on_beats(motion_beats_s, music_beats_s, *, window_s: float) -> np.ndarray:
    """Per motion beat, whether a music beat lies within +-``window_s`` of it (1 ns tolerance)."""
    music = as_times(music_beats_s, "music_beats_s")
    motion = as_times(motion_beats_s, "motion_beats_s")
    window = check_seconds(window_s, "window_s", allow_zero=True)
    return _nearest_distance(motion, music) <= window + TIME_TOL_S


def aligned_beat_ratio(music_beats_s, motion_beats_s, *, window_s: float) -> float:
    """Fraction of kinematic beats that lie within ``window_s`` of a music beat.

    Aristidou et al., Rhythm is a Dancer, §5.4.1, measure (b): "a kinematic and a
    musical beat are considered aligned if their distance is not larger than one
    frame" -- pass ``window_s = 1 / fps`` (``evaluate`` does). Their mocap scores 72.5 %.
    NaN when there are no kinematic beats; 0.0 when there are no music beats.
    """
    hits = on_beats(motion_beats_s, music_beats_s, window_s=window_s)
    return float(np.mean(hits)) if hits.size else _NAN


def accent_precision_recall(music_beats_s, motion_beats_s, *, window_s: float = DEFAULT_HIT_WINDOW_S
                            ) -> tuple[float, float]:
    """``(precision, recall)`` of a dance's visible accents against the music's beats.

    ``recall = hit_rate`` (music beats with a kinematic beat within +-``window_s``),
    ``precision = aligned_beat_ratio`` at the same window (kinematic beats within
    +-``window_s`` of a music beat). Both are needed: recall alone rewards a dance
    that stops everywhere, precision alone one that stops once.
    """
    return (aligned_beat_ratio(music_beats_s, motion_beats_s, window_s=window_s),
            hit_rate(music_beats_s, motion_beats_s, window_s=window_s))


def shifted_chance(music_beats_s, motion_beats_s, *, span_s: tuple[float, float],
                   window_s: float = DEFAULT_HIT_WINDOW_S, n_shifts: int = 100) -> tuple[float, float]:
    """``(precision, recall)`` expected by chance: the same kinematic beats, circularly shifted.

    The motion beats are rotated within ``span_s = (start, end)`` by ``n_shifts`` offsets
    spread over the span (skipping offsets within 2 windows of 0, which are the dance
    itself) and scored each time; the mean is what the dance's own accent
    rate and the music's beat rate give with no synchronisation at all. A dance at
    1.2x this is not synchronised, whatever its bookkeeping says (DESIGN.md).
    NaN where the unshifted metric is NaN.
    """
    music = as_times(music_beats_s, "music_beats_s")
    motion = as_times(motion_beats_s, "motion_beats_s")
    window = check_seconds(window_s, "window_s", allow_zero=True)
    start, end = float(span_s[0]), float(span_s[1])
    length = end - start
    if not (math.isfinite(length) and length > 0):
        raise InputError(f"span_s must be (start, end) seconds with end > start, got {span_s!r}")
    if music.size == 0 or motion.size == 0:
        return accent_precision_recall(music, motion, window_s=window)
    # Golden-ratio offsets cover the span evenly without locking onto a regular beat grid (evenly
    # spaced ones alias with it).
    offsets = (np.arange(1, int(n_shifts) + 1) * _GOLDEN % 1.0) * length
    offsets = offsets[(offsets > 2 * window) & (offsets < length - 2 * window)]
    scores = np.array([accent_precision_recall(music, np.sort((motion - start + o) % length + start),
                                               window_s=window) for o in offsets])
    return float(np.mean(scores[:, 0])), float(np.mean(scores[:, 1]))


def bar_accent_share(beat_times_s, beat_in_bar, accent_strength) -> tuple[float, int]:
    """Share of bars whose strongest visible accent falls on the downbeat, and the bars counted.

    ``beat_in_bar`` (B,) is each beat's position in its bar (0 = downbeat, as
    ``MusicFeatures.beat_in_bar``); ``accent_strength`` (B,) how strongly the dance
    marks each beat (``motion_metrics.beat_accent_strength``). Only complete bars with
    some accent are counted. Chance is ``1 / beats_per_bar``. NaN when no bar counts.
    """
    times = as_values(beat_times_s, "beat_times_s")
    pos = np.asarray(beat_in_bar)
    strength = as_values(accent_strength, "accent_strength")
    if not (times.size == pos.size == strength.size):
        raise InputError(f"beat_times_s ({times.size}), beat_in_bar ({pos.size}) and accent_strength "
                         f"({strength.size}) need one value per beat")
    starts = np.flatnonzero(pos == 0)
    hits, counted = 0, 0
    for a, b in zip(starts[:-1], starts[1:]):
        bar = strength[a:b]
        if b - a != int(pos[b - 1]) + 1 or not np.any(bar > 0):
            continue  # an incomplete bar (a metre change, a dropped beat) or no accent at all
        counted += 1
        hits += int(np.argmax(bar) == 0)
    return (hits / counted if counted else _NAN), counted


def dominant_beat_period(per_beat_values, *, periods=(2, 3, 4)) -> tuple[int | None, dict[int, float]]:
    """The period (in beats) at which a per-beat series repeats most strongly.

    The normalised autocorrelation of ``per_beat_values`` (e.g. the dance's kinetic
    energy per beat interval) at each lag in ``periods``; a waltz danced in three
    shows its peak at 3, an 8-count salsa at 2 or 4. Returns ``(best period, {lag: r})``;
    ``(None, {})`` for fewer than 3 full periods of values.
    """
    x = as_values(per_beat_values, "per_beat_values")
    lags = [int(p) for p in periods if x.size >= 3 * int(p)]
    x = x - x.mean()
    den = float(np.sum(x * x))
    if not lags or den == 0.0:
        return None, {}
    r = {lag: float(np.sum(x[:-lag] * x[lag:]) / den * x.size / (x.size - lag)) for lag in lags}
    return max(r, key=r.get), r


# ---------------------------------------------------------------------------------------------
# Beat tracking accuracy (music analysis against ground truth)

BEAT_TRACKING_KEYS = ("f_measure", "cmlc", "cmlt", "amlc", "amlt", "p_score")


def beat_tracking_scores(reference_beats_s, estimated_beats_s, *, window_s: float = DEFAULT_BEAT_WINDOW_S,
                         skip_s: float = DEFAULT_SKIP_S) -> dict[str, float]:
    """The standard beat-tracking scores of ``mir_eval.beat`` (Raffel et al. 2014).

    Beats before ``skip_s`` are removed from both lists first, as
    ``mir_eval.beat.trim_beats`` does (its default, 5 s, skips the part where a
    tracker is still finding the tempo; pass 0 to keep everything). Then:

    - ``f_measure``: F-measure of one-to-one matches within +-``window_s`` (70 ms);
    - ``cmlc``, ``cmlt``, ``amlc``, ``amlt``: continuity scores (correct / any metrical
      level, longest continuous segment / total), with mir_eval's tolerances of 17.5 %
      of the beat period for phase and period;
    - ``p_score``: McKinney's P-score (cross-correlation within 20 % of the median
      inter-beat interval).

    Values in [0, 1]. When no reference beat remains after trimming every score is
    NaN (nothing to be accurate about); when no estimated beat remains every score is
    0.0 (mir_eval's value). mir_eval's warnings about short lists are silenced.
    """
    ref = as_times(reference_beats_s, "reference_beats_s")
    est = as_times(estimated_beats_s, "estimated_beats_s")
    window = check_seconds(window_s, "window_s")
    skip = check_seconds(skip_s, "skip_s", allow_zero=True)
    ref, est = ref[ref >= skip], est[est >= skip]
    if ref.size == 0:
        return dict.fromkeys(BEAT_TRACKING_KEYS, _NAN)
    if est.size == 0:
        return dict.fromkeys(BEAT_TRACKING_KEYS, 0.0)
    if max(ref[-1], est[-1]) > 30000.0 or min(ref[0], est[0]) < 0:
        raise InputError("beat times must lie between 0 and 30000 s; are they in seconds (not frames or samples)?")
    import mir_eval.beat  # ~1 s to import: only when beat tracking is scored

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = mir_eval.beat.f_measure(ref, est, f_measure_threshold=window)
        cmlc, cmlt, amlc, amlt = mir_eval.beat.continuity(ref, est)
        p = mir_eval.beat.p_score(ref, est) if ref.size > 1 and est.size > 1 else 0.0
    return {"f_measure": float(f), "cmlc": float(cmlc), "cmlt": float(cmlt), "amlc": float(amlc),
            "amlt": float(amlt), "p_score": float(p)}


def beat_f_measure(reference_beats_s, estimated_beats_s, *, window_s: float = DEFAULT_BEAT_WINDOW_S,
                   skip_s: float = DEFAULT_SKIP_S) -> float:
    """``beat_tracking_scores(...)["f_measure"]``: F-measure of beats matched within +-``window_s``."""
    return beat_tracking_scores(reference_beats_s, estimated_beats_s, window_s=window_s,
                                skip_s=skip_s)["f_measure"]


# ---------------------------------------------------------------------------------------------
# Intensity correspondence, global structure, time warp, reference distributions


def _average_ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..n, ties sharing their average rank (as ``scipy.stats.rankdata``)."""
    _, inverse, counts = np.unique(x, return_inverse=True, return_counts=True)
    ends = np.cumsum(counts)
    return (ends - (counts - 1) / 2.0)[inverse]


def intensity_correlation(music_loudness_db, motion_energy) -> float:
    """Spearman rank correlation between music loudness and motion energy per beat interval.

    Xu et al.'s second requirement: "the motion intensity should be matched to that
    in the music" -- loud intervals danced with more kinetic energy. Both inputs
    have one value per beat interval, in the same order: ``music_loudness_db`` as
    ``MusicFeatures.intensity_db``, ``motion_energy`` the kinetic energy over the same
    intervals (``motion_metrics.beat_interval_energy``). Ranks make the score
    independent of units and of the dB scale::

        rho = pearson(rank(loudness), rank(energy))      (ties get average ranks)

    +1: energy rises with loudness everywhere; -1: the reverse. NaN when there are
    fewer than 3 intervals or either series is constant. Loudness may be -inf
    (silence); NaN is an error, as are lists of different lengths.
    """
    loud = as_values(music_loudness_db, "music_loudness_db", allow_inf=True)
    energy = as_values(motion_energy, "motion_energy")
    if loud.size != energy.size:
        raise InputError(f"music_loudness_db has {loud.size} values but motion_energy {energy.size}; "
                         "give one value per beat interval to both (B beats make B-1 intervals)")
    if loud.size < 3:
        return _NAN
    ra, rb = _average_ranks(loud), _average_ranks(energy)
    ra, rb = ra - ra.mean(), rb - rb.mean()
    den = math.sqrt(float(np.sum(ra * ra) * np.sum(rb * rb)))
    if den == 0.0:
        return _NAN
    return float(np.clip(np.sum(ra * rb) / den, -1.0, 1.0))


def signature_chi2(reference_signature, estimated_signature) -> float:
    """Chi-square distance between two motion signatures (motif histograms).

    Aristidou et al., Rhythm is a Dancer, eq. (11)::

        chi2(S1, S2) = 1/2 * sum_i (S1_i - S2_i)^2 / (S1_i + S2_i)

    over *normalised* histograms: both inputs are divided by their sums first
    (counts are fine). Bins empty in both contribute 0. The value lies in [0, 1]:
    0 for proportional histograms, 1 for histograms with no bin in common.
    Negative entries, NaN, all-zero histograms and different lengths raise
    ``InputError``.
    """
    from ..motion.motifs import chi2  # the one implementation; the motion layer owns motifs

    return chi2(as_values(reference_signature, "reference_signature"),
                as_values(estimated_signature, "estimated_signature"))


WARP_KEYS = ("median_abs_log2", "frac_over_10pct", "frac_over_25pct", "min", "max")


def time_warp_stats(warp_rates) -> dict[str, float]:
    """How strongly a dance was time-warped to land its beats on the music's.

    ``warp_rates`` are playback-speed factors, one per rendered beat piece (source
    seconds played per output second; 1 = the mocap's own speed, 2 = twice as fast),
    as in a dance's ``clip.meta["warp_rates"]``. Returns

    - ``median_abs_log2``: median of ``|log2 rate|`` (0 = unwarped, 1 = twice as fast
      or slow);
    - ``frac_over_10pct`` / ``frac_over_25pct``: fraction of pieces warped by more than
      10 % / 25 %, symmetric in speeding up and slowing down:
      ``max(rate, 1/rate) > 1.10`` (resp. 1.25);
    - ``min``, ``max``: the extreme rates.

    Xu et al. count "the temporal modification" among the sources of artefacts; this
    reports it. All values NaN for an empty list; rates must be finite and > 0.
    """
    rates = as_values(warp_rates, "warp_rates")
    if np.any(rates <= 0):
        raise InputError("warp_rates must be positive playback-speed factors (1 = unwarped), "
                         f"got {rates[rates <= 0][0]}")
    if rates.size == 0:
        return dict.fromkeys(WARP_KEYS, _NAN)
    factor = np.maximum(rates, 1.0 / rates)
    return {"median_abs_log2": float(np.median(np.abs(np.log2(rates)))),
            "frac_over_10pct": float(np.mean(factor > 1.10)),
            "frac_over_25pct": float(np.mean(factor > 1.25)),
            "min": float(rates.min()), "max": float(rates.max())}


def percentile_rank(value: float, reference) -> float:
    """Percentage (0-100) of ``reference`` values that are <= ``value``.

    Places one number in a reference distribution, e.g. a dance's largest
    transition jump among the per-frame jumps of its source mocap (100: larger than
    anything the mocap does). NaN when ``reference`` is empty or ``value`` is NaN.
    """
    ref = as_values(reference, "reference")
    v = float(value)
    if ref.size == 0 or math.isnan(v):
        return _NAN
    return float(100.0 * np.mean(ref <= v))
