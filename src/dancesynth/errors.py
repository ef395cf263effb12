"""The one exception family of dancesynth.

Every error a user can cause or meet is a ``DanceSynthError`` whose message says
what was wrong and what to do about it. The CLI prints the message on one line
and exits non-zero; library code never prints or exits.
"""


class DanceSynthError(Exception):
    """Base class of every error dancesynth raises on purpose."""


class InputError(DanceSynthError):
    """The user's input (a file, an argument, a song) cannot be used as given."""


class ModelError(DanceSynthError):
    """A database, graph or model is missing, corrupt or cannot serve the request."""


class SynthesisError(DanceSynthError):
    """Synthesis could not produce motion (for example, no path through a graph)."""
