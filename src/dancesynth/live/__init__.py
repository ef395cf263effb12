"""Live: music that is still arriving in, a dance out, segment by segment.

- ``sources``: audio from a file at real-time pace, standard input or an http(s)
  stream, decoded by ffmpeg into mono chunks; stalls and the end are reported.
- ``beats``: beat tracking on a stream (beats are final once given).
- ``runtime``: the double buffer of Xu et al.'s Fig. 1: while segment n plays,
  segment n+1 is synthesised by the engine's pure ``step``.
"""
