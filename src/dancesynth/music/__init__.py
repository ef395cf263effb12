"""Music analysis: beats, tempo, beat confidence and per-beat intensity.

``analyze_music`` is the entry point; the pure functions it is made of are public
too, so that streaming code can run them on segments:

- ``onset_envelope`` (numpy log-mel spectral flux) -> ``track_beats`` (tracker
  chosen by name, default ``"dp"``) -> beat times, tempo, confidence
- ``dp_beat_track``: Ellis' dynamic-programming beat tracker on any onset envelope
  at any frame rate; ``estimate_tempo``: its global tempo estimate
- ``beat_confidence`` (from ``beat_contrast`` and ``beat_onset_db``): how clearly the audio pulses
- ``beat_intensity_db``: sound pressure level of each beat interval (Xu et al. §3.3)
- ``steady_beat_grid``: the fallback beats when there is no clear pulse
- ``NoteSequence`` (Loi & Li's melody features), ``midi_notes`` (MIDI, mido) and
  ``read_notes`` (MIDI or a recording: ``audio_notes``, librosa's pYIN, imported on use)

The default path needs only numpy (and soundfile/soxr to decode): librosa is
imported only for ``tracker="librosa"``.
"""

from .analysis import SILENCE_PEAK_DB, analyze_music
from .beats import (DEFAULT_TRACKER, MIN_BEATS, MIN_CONFIDENCE, TRACKERS, beat_confidence, beat_contrast,
                    beat_onset_db, refine_beat_frames, sounding_span, steady_beat_grid, track_beats)
from .intensity import FLOOR_DB, beat_intensity_db, rms_db
from .melody import audio_notes, read_notes
from .notes import NoteSequence, midi_notes, read_midi
from .onset import ANALYSIS_SR, FEATURE_FPS, HOP_LENGTH, mel_filterbank, onset_envelope
from ..beat_tracking import dp_beat_track, estimate_tempo

__all__ = [
    "ANALYSIS_SR", "DEFAULT_TRACKER", "FEATURE_FPS", "FLOOR_DB", "HOP_LENGTH", "MIN_BEATS", "MIN_CONFIDENCE",
    "SILENCE_PEAK_DB", "TRACKERS", "analyze_music", "beat_confidence", "beat_contrast", "beat_intensity_db",
    "beat_onset_db", "dp_beat_track", "estimate_tempo", "mel_filterbank", "onset_envelope",
    "refine_beat_frames", "rms_db", "sounding_span", "steady_beat_grid", "track_beats",
    "NoteSequence", "audio_notes", "midi_notes", "read_midi", "read_notes",
]
