"""dancesynth: make a 3D character dance to music.

    >>> import dancesynth
    >>> clip = dancesynth.dance("song.ogg", style="salsa")
    >>> dancesynth.write_bvh("song.bvh", clip)

Everything but the errors loads on first use (numpy included), so ``import dancesynth``
stays light and the command line can start quietly even when interrupted at once.
"""

from .errors import DanceSynthError, InputError, ModelError, SynthesisError

__version__ = "0.1.0"

__all__ = ["dance", "batch", "list_styles", "read_bvh", "write_bvh", "analyze_music", "open_database",
           "MotionClip", "MusicFeatures", "Skeleton",
           "DanceSynthError", "InputError", "ModelError", "SynthesisError"]


def __getattr__(name):
    if name in ("MotionClip", "MusicFeatures", "Skeleton"):
        from . import types
        return getattr(types, name)
    if name in ("batch", "BatchResult"):
        from . import batching
        return getattr(batching, name)
    if name == "list_styles":
        from .motion.catalog import list_styles
        return list_styles
    if name in ("dance", "DanceConfig"):
        from . import api
        return getattr(api, name)
    if name in ("read_bvh", "write_bvh"):
        from .io import bvh
        return getattr(bvh, name)
    if name == "analyze_music":
        from .music import analyze_music
        return analyze_music
    if name == "open_database":
        from .motion.database import open_database
        return open_database
    raise AttributeError(f"module 'dancesynth' has no attribute '{name}'")
