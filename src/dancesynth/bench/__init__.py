"""``dancesynth bench``: the benchmark tables, on top of everything else.

- ``run``: ``run_bench`` runs the selected sections and writes ``bench.json``.
- ``speed`` (Xu Fig. 4, scaling, the pipeline), ``quality``, ``beats`` (beat tracking on
  generated songs), ``structure`` (Aristidou Table I and re-creation), ``accents``,
  ``realism``: one section each; ``common``: their configuration and helpers.
- ``groundtruth``: MIDI songs with exactly known beats rendered to audio by fluidsynth.

The metrics themselves are in ``dancesynth.eval``; nothing there imports from here.
"""
