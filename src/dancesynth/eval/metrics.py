"""The metric functions of the evaluation suite, in one namespace.

They live in two modules (each under 500 lines):

- ``beat_metrics``: metrics on arrays -- beat alignment (Beat Align Score in both
  directions, hit rate, Aristidou's kinematic-beat ratios), beat-tracking accuracy
  (``mir_eval.beat``), intensity correlation, motion-signature chi-square,
  time-warp statistics, percentile ranks;
- ``motion_metrics``: metrics of a ``MotionClip`` -- kinematic beats, beat-interval
  energy, angular-velocity jumps at transitions, jerk, foot skating, EDGE's PFC,
  ground penetration.

``dancesynth.eval.evaluate.evaluate`` runs them all on one motion and returns a
flat dict. Definitions, defaults and sources: ``docs/metrics.md``.
"""

from .beat_metrics import (
    accent_precision_recall,
    aligned_beat_ratio,
    bar_accent_share,
    beat_align_score,
    beat_count_ratio,
    beat_f_measure,
    beat_tracking_scores,
    dominant_beat_period,
    hit_rate,
    intensity_correlation,
    percentile_rank,
    shifted_chance,
    signature_chi2,
    time_warp_stats,
)
from .motion_metrics import (
    angular_velocity_jumps,
    beat_accent_strength,
    beat_interval_energy,
    feet_of,
    floor_height,
    foot_skate,
    ground_penetration,
    kinematic_beats,
    mean_jerk,
    pfc,
    transition_jump,
    transition_jumps,
)

__all__ = [
    "accent_precision_recall", "bar_accent_share", "beat_accent_strength", "dominant_beat_period",
    "shifted_chance", "aligned_beat_ratio", "angular_velocity_jumps", "beat_align_score", "beat_count_ratio", "beat_f_measure",
    "beat_interval_energy", "beat_tracking_scores", "feet_of", "floor_height", "foot_skate", "ground_penetration",
    "hit_rate", "intensity_correlation", "kinematic_beats", "mean_jerk", "percentile_rank", "pfc",
    "signature_chi2", "time_warp_stats", "transition_jump", "transition_jumps",
]
