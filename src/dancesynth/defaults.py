"""Product-wide defaults, each defined here once; the configs and the CLI read them from here
(a module without numpy, so the command line starts fast)."""

DEFAULT_FPS = 30.0          # frame rate of a dance
SEGMENT_S = 5.0             # streaming segment length (Xu et al. synthesise segment by segment)
BEAT_LATENCY_S = 1.5        # the streaming beat tracker gives beats this long after hearing them (live/beats.py)
FALLBACK_BPM = 100.0        # the tempo we dance at when the music has no clear beat
MAX_SONG_S = 15 * 60.0      # longer songs are refused unless the user raises the limit
#: The extensions a song may have where we look for songs (a music folder, an upload).
AUDIO_SUFFIXES = frozenset({".ogg", ".oga", ".wav", ".flac", ".mp3", ".m4a", ".opus", ".aac", ".webm", ".aif",
                            ".aiff"})
