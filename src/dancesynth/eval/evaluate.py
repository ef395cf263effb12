"""Evaluate one motion against its music and its source mocap: a flat dict of numbers.

``evaluate(motion, music_beats_s=..., ...)`` runs every metric of ``metrics`` that
the given inputs allow and returns ``{key: float | int | None}`` -- JSON-ready, keys
in the display order of ``METRICS``, ``None`` where a metric does not apply (no music
given, no transitions, no kinematic beats, a skeleton without legs ...).
``format_table`` prints several such dicts side by side. No file I/O, no printing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import InputError, ModelError
from ..kinematics import clip_fk
from ..motion.beats import stop_depths
from ..motion.resample import sample_frames
from ..types import MotionClip
from . import beat_metrics as bm
from . import motion_metrics as mm


@dataclass(frozen=True)
class EvalParams:
    """Every tunable of ``evaluate``, in seconds / metres (the one source of its defaults)."""

    sigma_s: float = bm.DEFAULT_SIGMA_S                       # Beat Align Score Gaussian width
    hit_window_s: float = bm.DEFAULT_HIT_WINDOW_S             # hit_rate tolerance
    aligned_window_s: float | None = None                     # aligned_beat_ratio; None = one frame (1/fps)
    beat_smooth_s: float = mm.DEFAULT_SMOOTH_S                # kinematic beats: Savitzky-Golay window
    beat_polyorder: int = mm.DEFAULT_POLYORDER                # ... and its polynomial order
    beat_min_separation_s: float = mm.DEFAULT_MIN_SEPARATION_S
    beat_min_prominence_frac: float = mm.DEFAULT_MIN_PROMINENCE_FRAC
    visible_stop_depth: float = mm.VISIBLE_STOP_DEPTH         # a kinematic beat this deep is a visible accent
    transition_radius_s: float = mm.DEFAULT_TRANSITION_RADIUS_S  # search +- this around a transition
    contact_height_m: float = mm.DEFAULT_CONTACT_HEIGHT_M     # foot on the floor: within this of it
    floor_m: float | None = None                              # None: estimated (median lowest foot point)


@dataclass(frozen=True)
class MetricInfo:
    """How to show one key of ``evaluate``'s result."""

    label: str
    unit: str     # "" for unitless
    better: str   # "higher", "lower", "≈1", "≤1", "≈mocap" (compare with the mocap's column), "info"
    group: str    # "general", "beat alignment", "intensity", "smoothness", "contact", "time warp"


def _m(label, unit, better, group):
    return MetricInfo(label, unit, better, group)


#: Every key ``evaluate`` returns, in display order.
METRICS: dict[str, MetricInfo] = {
    "duration_s": _m("duration", "s", "info", "general"),
    "n_frames": _m("frames", "", "info", "general"),
    "n_music_beats": _m("music beats (within the motion)", "", "info", "beat alignment"),
    "n_kinematic_beats": _m("kinematic beats", "", "info", "beat alignment"),
    "bas_motion": _m("Beat Align Score, over motion beats (FACT)", "", "higher", "beat alignment"),
    "bas_music": _m("Beat Align Score, over music beats (Bailando)", "", "higher", "beat alignment"),
    "hit_rate": _m("music beats with a kinematic beat within the hit window", "", "higher", "beat alignment"),
    "kinematic_beat_ratio": _m("kinematic / music beats (Aristidou 5.4.1a)", "", "≈mocap", "beat alignment"),
    "aligned_beat_ratio": _m("kinematic beats within 1 frame of a music beat (5.4.1b)", "", "higher",
                             "beat alignment"),
    "accent_precision": _m("kinematic beats within the hit window of a music beat (precision)", "", "higher",
                           "beat alignment"),
    "accent_precision_chance": _m("... by chance (kinematic beats circularly shifted)", "", "info", "beat alignment"),
    "accent_precision_x_chance": _m("precision / chance", "", "higher", "beat alignment"),
    "accent_recall": _m("music beats with a kinematic beat within the hit window (recall)", "", "higher",
                        "beat alignment"),
    "accent_recall_chance": _m("... by chance (kinematic beats circularly shifted)", "", "info", "beat alignment"),
    "accent_recall_x_chance": _m("recall / chance", "", "higher", "beat alignment"),
    "stop_depth_on_beats": _m("median stop depth of the kinematic beats on a music beat (1 = a full stop)", "",
                              "≈mocap", "beat alignment"),
    "visible_accent_precision": _m("kinematic beats as deep as the mocap's accents, on a music beat (precision)",
                                   "", "higher", "beat alignment"),
    "visible_accent_precision_chance": _m("... by chance (circularly shifted)", "", "info", "beat alignment"),
    "visible_accent_precision_x_chance": _m("visible precision / chance", "", "higher", "beat alignment"),
    "visible_accent_recall": _m("music beats with a kinematic beat as deep as the mocap's accents (recall)", "",
                                "higher", "beat alignment"),
    "visible_accent_recall_chance": _m("... by chance (circularly shifted)", "", "info", "beat alignment"),
    "visible_accent_recall_x_chance": _m("visible recall / chance", "", "higher", "beat alignment"),
    "beats_per_bar": _m("music beats per bar", "", "info", "bars"),
    "downbeat_precision": _m("kinematic beats on a downbeat (precision)", "", "higher", "bars"),
    "downbeat_precision_chance": _m("... by chance", "", "info", "bars"),
    "downbeat_recall": _m("downbeats with a kinematic beat (recall)", "", "higher", "bars"),
    "downbeat_recall_chance": _m("... by chance", "", "info", "bars"),
    "bar_accent_on_downbeat": _m("bars whose strongest accent is on the downbeat", "", "higher", "bars"),
    "bar_accent_chance": _m("... by chance (1 / beats per bar)", "", "info", "bars"),
    "n_bars_counted": _m("bars with an accent (counted above)", "", "info", "bars"),
    "energy_period_beats": _m("strongest period of per-beat kinetic energy (2-4 beats)", "beats", "info", "bars"),
    "intensity_spearman": _m("Spearman(loudness, kinetic energy) per beat interval", "", "higher", "intensity"),
    "n_transitions": _m("transitions", "", "info", "smoothness"),
    "max_transition_jump_deg_s": _m("largest angular-velocity jump at a transition", "deg/s", "lower",
                                    "smoothness"),
    "transition_jump_pct_in_mocap": _m("percentile of that jump among mocap frames", "%", "lower", "smoothness"),
    "transition_jump_vs_mocap_p99": _m("that jump / mocap 99th-percentile jump", "", "≤1", "smoothness"),
    "transition_frac_over_mocap_p99": _m("transitions jumping more than mocap p99", "", "lower", "smoothness"),
    "jump_p99_deg_s": _m("99th-percentile angular-velocity jump, all frames", "deg/s", "≈mocap", "smoothness"),
    "jump_max_deg_s": _m("largest angular-velocity jump, all frames", "deg/s", "lower", "smoothness"),
    "mocap_jump_p99_deg_s": _m("mocap 99th-percentile jump (at this fps)", "deg/s", "info", "smoothness"),
    "jump_p99_vs_mocap": _m("99th-percentile jump / mocap's", "", "≈1", "smoothness"),
    "jerk_m_s3": _m("mean joint jerk", "m/s³", "≈mocap", "smoothness"),
    "joint_speed_p99_m_s": _m("99th-percentile joint speed", "m/s", "≈mocap", "smoothness"),
    "joint_speed_p99_vs_mocap": _m("99th-percentile joint speed / mocap's", "", "≈1", "smoothness"),
    "root_travel_m_s": _m("mean root speed across the floor", "m/s", "≈mocap", "smoothness"),
    "root_travel_vs_mocap": _m("mean root speed across the floor / mocap's", "", "≈1", "smoothness"),
    "jerk_vs_mocap": _m("mean jerk / mocap's", "", "≈1", "smoothness"),
    "foot_skate_m_s": _m("foot speed while on the floor", "m/s", "lower", "contact"),
    "pfc": _m("Physical Foot Contact score (EDGE)", "", "lower", "contact"),
    "foot_skate_vs_mocap": _m("foot speed on the floor / the style's mocap's", "", "≤1.1", "contact"),
    "pfc_vs_mocap": _m("PFC / the style's mocap's", "", "≤1.1", "contact"),
    "ground_penetration_m": _m("mean depth of the lowest foot below the floor", "m", "lower", "contact"),
    "ground_penetration_max_m": _m("largest depth below the floor", "m", "lower", "contact"),
    "warp_median_abs_log2": _m("median |log2 time-warp rate|", "", "lower", "time warp"),
    "warp_frac_over_10pct": _m("beat pieces warped by more than 10 %", "", "lower", "time warp"),
    "warp_frac_over_25pct": _m("beat pieces warped by more than 25 %", "", "lower", "time warp"),
    "warp_rate_min": _m("slowest playback rate", "", "≈1", "time warp"),
    "warp_rate_max": _m("fastest playback rate", "", "≈1", "time warp"),
    "form_score": _m("structure consistency: music vs dance bar similarity (r, eval.form)", "", "higher", "form"),
    "form_chance": _m("... with the dance's bars shuffled within sections", "", "info", "form"),
}


def evaluate(motion: MotionClip, *, music_beats_s=None, music_loudness_db=None, beat_in_bar=None,
             beats_per_bar: int | None = None, transitions_s=None,
             warp_rates=None, mocap: Sequence[MotionClip] | MocapReference | None = None,
             params: EvalParams = EvalParams()) -> dict[str, float | int | None]:
    """Every applicable metric of ``motion``; the keys of ``METRICS``, ``None`` where not applicable.

    - ``music_beats_s``: the music's beats (increasing seconds, ``MusicFeatures.beat_times_s``);
      beats outside the motion's time span (0 to ``motion.duration_s``, +- one frame)
      are ignored for the beat-alignment metrics. Without them there is no beat or
      intensity metric.
    - ``music_loudness_db``: one value per interval between consecutive
      ``music_beats_s`` (``MusicFeatures.intensity_db``); the motion's kinetic energy
      is integrated over the same intervals (those entirely inside the motion).
    - ``transitions_s``: times where the dance jumps between source clips (a dance's
      ``clip.meta["transition_times_s"]``). Unknown (a BVH from disk): leave ``None``;
      the all-frames jump statistics still say how smooth the motion is.
    - ``warp_rates``: playback-speed factor per beat piece (``clip.meta["warp_rates"]``).
    - ``mocap``: the source mocap clips of the dance's style, each evaluated on its own
      (clips are never concatenated: the seam would be a fake jump) after resampling
      to ``motion.fps``; they give the reference distributions for the ``*mocap*`` keys.
      A ``MocapReference`` from ``mocap_reference(clips, motion.fps)`` does the same
      without analysing the clips again.

    Raises ``InputError`` for unusable input (an empty or NaN motion, unsorted or NaN
    beats, a loudness list of the wrong length, loudness without beats).
    """
    p = params
    mm.check_motion(motion)
    out: dict[str, float | int | None] = dict.fromkeys(METRICS)
    fps = motion.fps
    g_rot, g_pos = clip_fk(motion)
    out["duration_s"] = motion.duration_s
    out["n_frames"] = motion.n_frames

    kin_s, _, smooth = mm.kinematic_beats(motion, smooth_s=p.beat_smooth_s, polyorder=p.beat_polyorder,
                                     min_separation_s=p.beat_min_separation_s,
                                     min_prominence_frac=p.beat_min_prominence_frac, global_pos=g_pos)
    out["n_kinematic_beats"] = int(kin_s.size)
    if music_beats_s is not None:
        out.update(_music_metrics(motion, kin_s, smooth, music_beats_s, music_loudness_db, g_pos, p))
        if beat_in_bar is not None:
            out.update(_bar_metrics(motion, kin_s, smooth, music_beats_s, beat_in_bar, beats_per_bar, g_pos, p))
    elif music_loudness_db is not None:
        raise InputError("music_loudness_db needs music_beats_s: it holds one value per interval between beats")

    jumps = mm.angular_velocity_jumps(motion)
    inner = jumps[1:-1]
    if inner.size:
        out["jump_p99_deg_s"] = float(np.percentile(inner, 99))
        out["jump_max_deg_s"] = float(inner.max())
    at_transitions = np.zeros(0)
    if transitions_s is not None:
        at_transitions = mm.transition_jumps(motion, transitions_s, radius_s=p.transition_radius_s,
                                             jumps_deg_s=jumps)
        out["n_transitions"] = int(at_transitions.size)
        if at_transitions.size:
            out["max_transition_jump_deg_s"] = float(at_transitions.max())
    out["jerk_m_s3"] = mm.mean_jerk(motion, global_pos=g_pos)
    if motion.n_frames >= 2:
        out["joint_speed_p99_m_s"] = float(np.percentile(mm.joint_speeds(motion, global_pos=g_pos), 99))
        out["root_travel_m_s"] = mm.root_travel_speed(motion)

    try:
        feet = mm.feet_of(motion, global_rot=g_rot, global_pos=g_pos)
    except ModelError:
        feet = None  # no recognisable legs: the contact metrics do not apply
    if feet is not None:
        out["foot_skate_m_s"] = mm.foot_skate(motion, height_tol_m=p.contact_height_m, floor_m=p.floor_m,
                                              global_rot=g_rot, global_pos=g_pos)
        out["pfc"] = mm.pfc(motion, global_rot=g_rot, global_pos=g_pos)
        out["ground_penetration_m"] = mm.ground_penetration(motion, floor_m=p.floor_m, global_rot=g_rot,
                                                            global_pos=g_pos)
        out["ground_penetration_max_m"] = mm.ground_penetration(motion, floor_m=p.floor_m, statistic="max",
                                                                global_rot=g_rot, global_pos=g_pos)

    if isinstance(mocap, MocapReference):
        if abs(mocap.fps - fps) > 1e-6 * fps:
            raise InputError(f"the mocap reference was computed at {mocap.fps:g} fps but the motion runs at "
                             f"{fps:g} fps; use mocap_reference(clips, motion.fps)")
        out.update(_mocap_comparison(mocap, out, at_transitions))
    elif mocap is not None and len(mocap):
        out.update(_mocap_comparison(mocap_reference(mocap, fps), out, at_transitions))
    if warp_rates is not None:
        out.update({_WARP_KEYS[k]: v for k, v in bm.time_warp_stats(warp_rates).items()})
    return {k: _plain(v) for k, v in out.items()}


_WARP_KEYS = {"median_abs_log2": "warp_median_abs_log2", "frac_over_10pct": "warp_frac_over_10pct",
              "frac_over_25pct": "warp_frac_over_25pct", "min": "warp_rate_min", "max": "warp_rate_max"}


def _music_metrics(motion, kin_s, smooth, music_beats_s, music_loudness_db, g_pos, p: EvalParams) -> dict:
    beats = bm.as_values(music_beats_s, "music_beats_s")
    if np.any(np.diff(beats) <= 0):
        raise InputError("music_beats_s must be strictly increasing seconds (as MusicFeatures.beat_times_s); "
                         "sort them and drop duplicates (and their loudness values)")
    frame = 1.0 / motion.fps
    music = beats[(beats >= -frame) & (beats <= motion.duration_s + frame)]
    aligned_window = frame if p.aligned_window_s is None else p.aligned_window_s
    out = {
        "n_music_beats": int(music.size),
        "bas_motion": bm.beat_align_score(music, kin_s, sigma_s=p.sigma_s, average_over="motion"),
        "bas_music": bm.beat_align_score(music, kin_s, sigma_s=p.sigma_s, average_over="music"),
        "hit_rate": bm.hit_rate(music, kin_s, window_s=p.hit_window_s),
        "kinematic_beat_ratio": bm.beat_count_ratio(music, kin_s),
        "aligned_beat_ratio": bm.aligned_beat_ratio(music, kin_s, window_s=aligned_window),
    }
    span = (0.0, motion.duration_s)
    # Every speed minimum, then only those that stop the body as much as the mocap's accents do: easing
    # a glide makes regular shallow dips, which the first counts and the second does not.
    depth = stop_depths(smooth, np.round(kin_s * motion.fps).astype(np.int64))
    for prefix, kin in (("", kin_s), ("visible_", kin_s[depth >= p.visible_stop_depth])):
        precision, recall = bm.accent_precision_recall(music, kin, window_s=p.hit_window_s)
        chance_p, chance_r = bm.shifted_chance(music, kin, span_s=span, window_s=p.hit_window_s)
        out.update({f"{prefix}accent_precision": precision, f"{prefix}accent_precision_chance": chance_p,
                    f"{prefix}accent_precision_x_chance": _ratio(precision, chance_p),
                    f"{prefix}accent_recall": recall, f"{prefix}accent_recall_chance": chance_r,
                    f"{prefix}accent_recall_x_chance": _ratio(recall, chance_r)})
    on_beat = bm.on_beats(kin_s, music, window_s=p.hit_window_s)
    out["stop_depth_on_beats"] = float(np.median(depth[on_beat])) if on_beat.any() else None
    if music_loudness_db is not None:
        loud = bm.as_values(music_loudness_db, "music_loudness_db", allow_inf=True)
        if loud.size != max(beats.size - 1, 0):
            raise InputError(f"music_loudness_db has {loud.size} values for {beats.size} music beats; "
                             f"it needs one per beat interval ({max(beats.size - 1, 0)}), "
                             "as MusicFeatures.intensity_db")
        energy = mm.beat_interval_energy(motion, beats, global_pos=g_pos)
        inside = np.isfinite(energy)
        out["intensity_spearman"] = bm.intensity_correlation(loud[inside], energy[inside])
    return out


def _bar_metrics(motion, kin_s, smooth, music_beats_s, beat_in_bar, beats_per_bar, g_pos, p: EvalParams) -> dict:
    beats = bm.as_values(music_beats_s, "music_beats_s")
    pos = np.asarray(beat_in_bar)
    if pos.shape != beats.shape or not beats_per_bar or np.any(pos < 0) or np.any(pos >= beats_per_bar):
        raise InputError(f"beat_in_bar needs one position in [0, beats_per_bar) per music beat ({beats.size}); "
                         "pass MusicFeatures.beat_in_bar and .beats_per_bar")
    frame = 1.0 / motion.fps
    inside = (beats >= -frame) & (beats <= motion.duration_s + frame)
    beats, pos = beats[inside], pos[inside]
    downbeats = beats[pos == 0]
    precision, recall = bm.accent_precision_recall(downbeats, kin_s, window_s=p.hit_window_s)
    chance_p, chance_r = bm.shifted_chance(downbeats, kin_s, span_s=(0.0, motion.duration_s),
                                           window_s=p.hit_window_s)
    strength = mm.beat_accent_strength(beats, kin_s, smooth, motion.fps, window_s=p.hit_window_s)
    share, counted = bm.bar_accent_share(beats, pos, strength)
    energy = mm.beat_interval_energy(motion, beats, global_pos=g_pos)
    period, _ = bm.dominant_beat_period(energy[np.isfinite(energy)])
    return {"beats_per_bar": int(beats_per_bar), "downbeat_precision": precision,
            "downbeat_precision_chance": chance_p, "downbeat_recall": recall, "downbeat_recall_chance": chance_r,
            "bar_accent_on_downbeat": share, "bar_accent_chance": 1.0 / beats_per_bar, "n_bars_counted": counted,
            "energy_period_beats": period}


@dataclass(frozen=True, eq=False)
class MocapReference:
    """What ``evaluate`` compares a motion with, from its source mocap, computed once at ``fps``.

    ``jumps_deg_s``: the per-frame angular-velocity jumps of every clip's interior
    frames, pooled (each clip on its own: never across a seam between clips);
    ``jerk_m_s3``: the mean jerk over all clips' frames (NaN when no clip has 4 frames);
    ``joint_speed_p99_m_s`` and ``root_travel_m_s``: joint speed and root travel, pooled over clips;
    ``foot_skate_m_s`` and ``pfc``: the clips' foot skating, frame-weighted means (NaN without legs).
    """

    fps: float
    jumps_deg_s: np.ndarray
    jerk_m_s3: float
    n_clips: int
    joint_speed_p99_m_s: float = float("nan")
    root_travel_m_s: float = float("nan")
    foot_skate_m_s: float = float("nan")
    pfc: float = float("nan")


def mocap_reference(mocap: Sequence[MotionClip], fps: float) -> MocapReference:
    """The reference distributions of ``mocap`` clips resampled to ``fps``, for ``evaluate(mocap=...)``.

    Pass the result instead of the clips when several motions are evaluated against
    the same mocap, so that it is analysed once.
    """
    if not fps > 0:
        raise InputError(f"fps must be positive, got {fps!r}")
    jumps, speeds, jerk_sum, jerk_n, travel, travel_n = [], [], 0.0, 0, 0.0, 0
    feet = []  # (skate, pfc, frames) per clip with legs
    for i, clip in enumerate(mocap):
        clip = _at_fps(mm.check_motion(clip, f"mocap[{i}]"), fps)
        jumps.append(mm.angular_velocity_jumps(clip)[1:-1])
        g_rot, g_pos = clip_fk(clip)  # once per clip, for every metric below
        if clip.n_frames >= 2:
            speeds.append(mm.joint_speeds(clip, global_pos=g_pos).ravel())
            travel += mm.root_travel_speed(clip) * (clip.n_frames - 1)
            travel_n += clip.n_frames - 1
            try:
                feet.append((mm.foot_skate(clip, global_rot=g_rot, global_pos=g_pos),
                             mm.pfc(clip, global_rot=g_rot, global_pos=g_pos), clip.n_frames))
            except ModelError:
                pass  # no recognisable legs
        if clip.n_frames >= 4:
            jerk_sum += mm.mean_jerk(clip, global_pos=g_pos) * (clip.n_frames - 3)
            jerk_n += clip.n_frames - 3
    nan = float("nan")
    feet = np.array([f for f in feet if np.isfinite(f[0]) and np.isfinite(f[1])]).reshape(-1, 3)
    skate, pfc = ((np.average(feet[:, 0], weights=feet[:, 2]), np.average(feet[:, 1], weights=feet[:, 2]))
                  if len(feet) else (nan, nan))
    return MocapReference(float(fps), np.concatenate(jumps) if jumps else np.zeros(0),
                          jerk_sum / jerk_n if jerk_n else nan, len(jumps),
                          float(np.percentile(np.concatenate(speeds), 99)) if speeds else nan,
                          travel / travel_n if travel_n else nan, float(skate), float(pfc))


def _mocap_comparison(ref: MocapReference, out: dict, at_transitions: np.ndarray) -> dict:
    """The ``*mocap*`` keys: the motion's jumps and jerk against its source clips' own."""
    res = {"jerk_vs_mocap": _ratio(out["jerk_m_s3"], ref.jerk_m_s3),
           "joint_speed_p99_vs_mocap": _ratio(out["joint_speed_p99_m_s"], ref.joint_speed_p99_m_s),
           "root_travel_vs_mocap": _ratio(out["root_travel_m_s"], ref.root_travel_m_s),
           "foot_skate_vs_mocap": _ratio(out["foot_skate_m_s"], ref.foot_skate_m_s),
           "pfc_vs_mocap": _ratio(out["pfc"], ref.pfc)}
    if ref.jumps_deg_s.size:
        p99 = float(np.percentile(ref.jumps_deg_s, 99))
        res["mocap_jump_p99_deg_s"] = p99
        res["jump_p99_vs_mocap"] = _ratio(out["jump_p99_deg_s"], p99)
        if at_transitions.size:
            top = float(at_transitions.max())
            res["transition_jump_pct_in_mocap"] = bm.percentile_rank(top, ref.jumps_deg_s)
            res["transition_jump_vs_mocap_p99"] = _ratio(top, p99)
            res["transition_frac_over_mocap_p99"] = float(np.mean(at_transitions > p99))
    return res


def _ratio(a, b) -> float | None:
    """``a / b``, or None when either is missing or ``b`` is not a positive number."""
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) or b <= 0:
        return None
    return a / b


def _at_fps(clip: MotionClip, fps: float) -> MotionClip:
    """``clip`` resampled to ``fps`` (frame-rate-dependent metrics compare like with like)."""
    if abs(clip.fps - fps) < 1e-6 * fps:
        return clip
    step = clip.fps / fps
    positions = np.arange(int(np.floor((clip.n_frames - 1) / step + 1e-9)) + 1) * step
    local_rot, root_pos, _ = sample_frames(clip.local_rot, clip.root_pos, positions)
    local_pos = None
    if clip.local_pos is not None:
        lo = np.minimum(np.floor(positions).astype(np.int64), clip.n_frames - 1)
        hi = np.minimum(lo + 1, clip.n_frames - 1)
        a = (positions - lo)[:, None, None]
        local_pos = clip.local_pos[lo] * (1.0 - a) + clip.local_pos[hi] * a
    return MotionClip(clip.skeleton, fps, root_pos, local_rot, local_pos, meta=dict(clip.meta))


def _plain(v):
    """JSON-ready: ints stay ints, NaN / inf / None become None, numpy scalars become floats."""
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    v = float(v)
    return v if math.isfinite(v) else None


def format_table(columns: dict[str, dict]) -> str:
    """A plain-text table: one row per metric (``METRICS`` order, grouped), one column per motion.

    ``columns`` maps a column title to an ``evaluate`` result, e.g.
    ``{"dance": evaluate(dance, ...), "reference": evaluate(mocap_clip, ...)}``. Rows
    missing from every column are left out; keys unknown to ``METRICS`` follow under
    "other". ``None`` (and NaN) shows as "—".
    """
    keys = [k for k in METRICS if any(k in c for c in columns.values())]
    extra = sorted({k for c in columns.values() for k in c} - set(METRICS))
    names = list(columns)
    head = ["metric", "unit", "better", *names]
    rows: list[list[str] | str] = []
    group = None
    for k in keys + extra:
        info = METRICS.get(k, MetricInfo(k, "", "", "other"))
        if info.group != group:
            group = info.group
            rows.append(group)
        rows.append([f"  {info.label}", info.unit, info.better, *(_cell(columns[n].get(k)) for n in names)])
    table = [r for r in rows if isinstance(r, list)]
    widths = [max(len(r[i]) for r in [head, *table]) for i in range(len(head))]

    def line(cells):
        left = [c.ljust(w) for c, w in zip(cells[:3], widths)]
        right = [c.rjust(w) for c, w in zip(cells[3:], widths[3:])]
        return "  ".join(left + right).rstrip()

    text = [line(head), "  ".join("-" * w for w in widths)]
    text += [r if isinstance(r, str) else line(r) for r in rows]
    return "\n".join(text)


def _cell(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if v != 0 and (abs(v) >= 1e6 or abs(v) < 1e-3):
        return f"{v:.3e}"
    if abs(v) >= 1000:
        return f"{v:.0f}"
    return f"{v:.4g}"
