"""The learned pose generator of Aristidou et al. §4 (``dance --engine neural``, ``dancesynth train``).

Importing this package imports no torch; ``model``, ``losses``, ``train`` and the
generation in ``engine`` do. See docs/neural.md.
"""
