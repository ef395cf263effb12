"""Evaluation: metrics for a dance against its music.

- ``metrics`` / ``evaluate``: pure metric functions and ``evaluate()`` returning a dict
  (beat alignment, intensity correspondence, smoothness, foot contact, time warp,
  signature distance, beat-tracking accuracy); ``artefacts``, ``realism``: snaps and
  FID/diversity.
- ``report``: ``dancesynth eval`` as a library call (the only module here that reads files).

Metrics import analysis layers and types only, never synthesis engines. The benchmarks
that use them are ``dancesynth.bench``.
"""
