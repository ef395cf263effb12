"""Exporters that turn a dance into something to watch: MP4 video (``render_video``).

The renderer pulls in PIL and runs ffmpeg, so it is imported only when used.
"""

__all__ = ["render_video", "render_video_files"]


def __getattr__(name):
    if name in __all__:
        from . import video
        return getattr(video, name)
    raise AttributeError(f"module 'dancesynth.export' has no attribute '{name}'")
