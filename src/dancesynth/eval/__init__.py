"""Evaluation: metrics for a dance against its music, generated ground truth, benchmarks.

- ``metrics`` / ``evaluate``: pure metric functions and ``evaluate()`` returning a dict
  (beat alignment, intensity correspondence, smoothness, foot contact, time warp,
  signature distance, beat-tracking accuracy).
- ``groundtruth``: MIDI songs with exactly known beats rendered to audio by fluidsynth.
- ``bench``: the benchmark tables of ``dancesynth bench``.

Metrics import analysis layers and types only, never synthesis engines; the
benchmark sits on top of everything.
"""
