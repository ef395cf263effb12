"""The choreography engine (Aristidou et al., Rhythm is a Dancer, §5.2.4-5.2.5, §5.5):
a motif per beat by eq. (5) or by the user's constraints, danced with real mocap words."""

from .engine import choreography_dance, reference_motifs
from .level import constraint_beats, eq5_probabilities, parse_motif_at, plan_motifs, recreate_plan
from .mixer import MixerConfig, mix, word_bank

__all__ = ["choreography_dance", "reference_motifs", "constraint_beats", "eq5_probabilities", "parse_motif_at",
           "plan_motifs", "recreate_plan", "MixerConfig", "mix", "word_bank"]
