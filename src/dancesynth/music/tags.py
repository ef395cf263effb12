"""A song file's genre tag, and the dance genre families it suggests.

``read_genre_tag(path)`` reads the genre a tagger wrote into an audio file:

- ID3 (mp3, and the ``id3`` chunk of WAV/AIFF): TCON, including ID3v1 numeric
  genres (``"(17)"``, ``"17"`` or an ID3v1 tag's genre byte -> ``"Rock"``)
- Vorbis comments (ogg, opus, flac): GENRE
- MP4/M4A: the ``©gen`` atom, and the numeric ``gnre`` atom
- WAV: the RIFF ``LIST``/``INFO`` chunk's IGNR (or an ID3 chunk)

It uses mutagen when it is installed (ffprobe, bounded by a timeout, reads the
formats mutagen does not know, or everything when mutagen is missing). It never
raises for a tag problem: a file without a genre, a file that is not audio or one
that cannot be read gives ``None``, and the song is still danced. Only the given
path is opened, and only when it is a regular file itself (not a symbolic link,
FIFO, device or directory); ffprobe is kept to that file (``file:`` protocol only,
audio demuxers only, so no playlist or concat script can make it open another).

``genre_families(tag)`` maps a tag (``"Hip-Hop"``, ``"hip hop"``, ``"K-Pop"``,
``"R&B"``, ``"Latin Pop"``, ``"Jazz/Swing"``...) onto the dance genre families of
``FAMILIES`` through the small table ``GENRE_TABLE``, most specific first.
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import stat
import struct
import subprocess
import unicodedata
from typing import BinaryIO, Iterable

try:  # the preferred reader; ffprobe stands in without it
    import mutagen
    from mutagen.id3 import ID3, TCON
    from mutagen.mp4 import MP4Tags
    from mutagen.wave import WAVE
except ImportError:  # pragma: no cover - exercised by monkeypatching ``mutagen`` to None
    mutagen = None

__all__ = ["FAMILIES", "FFPROBE_TIMEOUT_S", "GENRE_TABLE", "genre_families", "read_genre_tag"]

# ---------------------------------------------------------------------------
# Genre families
# ---------------------------------------------------------------------------

# The dance genre families a tag can suggest. "pop" is the catch-all, so it comes
# last whenever a tag suggests a more specific family too.
FAMILIES = ("hiphop", "salsa", "indian", "jazz", "classical", "pop")

# Tags (case, spaces, hyphens, "&"/"and" and accents do not matter: "hip-hop" is
# also "Hip Hop", "hiphop", "HIP_HOP") -> families,
# most specific first. A tag of several words that is not a row itself is read
# word by word ("Latin Pop" -> latin + pop; "Alternative Hip Hop" -> hip hop).
GENRE_TABLE: tuple[tuple[tuple[str, ...], tuple[str, ...]], ...] = (
    # tags                                                          families
    (("hip-hop", "rap", "trap", "gangsta rap", "crunk",
      "drill", "grime"),                                            ("hiphop", "pop")),
    (("pop", "dance-pop", "k-pop", "j-pop", "c-pop", "synth-pop",
      "electropop", "teen pop", "pop rock"),                        ("pop",)),
    (("dance", "electronic", "electronica", "edm", "house", "techno",
      "trance", "electro", "eurodance", "dubstep", "drum and bass",
      "drum n bass", "dancehall", "disco", "funk"),                 ("pop",)),
    (("r&b", "rnb", "rhythm and blues", "contemporary r&b", "soul"),  ("pop",)),
    (("rock",),                                                     ("pop",)),
    (("latin", "salsa", "mambo", "cha-cha", "cha-cha-cha", "bachata",
      "merengue", "reggaeton", "cumbia", "latino", "latina"),                         ("salsa", "pop")),
    (("indian", "bollywood", "bhangra", "filmi", "world"),          ("indian",)),
    (("jazz", "swing", "ragtime", "blues", "big band", "broadway",
      "show tunes", "musical", "bebop", "dixieland", "charleston",
      "lindy hop"),                                                 ("jazz",)),
    (("electro swing", "rock and roll", "rock n roll", "rockabilly"), ("jazz", "pop")),
    (("classical", "ballet", "waltz", "orchestral", "soundtrack",
      "film score", "opera", "baroque", "symphony", "chamber music"), ("classical",)),
)

_MAX_TAG_CHARS = 1000


def _words(text: str) -> list[str]:
    """Lower-case ASCII words: accents dropped, apostrophes joined, '&' read as 'and'."""
    text = unicodedata.normalize("NFKD", text)
    text = "".join(c for c in text if not unicodedata.combining(c)).casefold()
    text = re.sub(r"['\u2019`]", "", text).replace("&", " and ")
    return re.findall(r"[a-z0-9]+", text)


def _build_lookup() -> tuple[dict[str, tuple[str, ...]], int]:
    lookup: dict[str, tuple[str, ...]] = {}
    longest = 1
    for tags, families in GENRE_TABLE:
        if not set(families) <= set(FAMILIES):
            raise ValueError(f"GENRE_TABLE names an unknown family in {families}")
        for tag in tags:
            words = _words(tag)
            key = "".join(words)
            if key in lookup:
                raise ValueError(f"{tag!r} is in GENRE_TABLE twice")
            lookup[key] = families
            longest = max(longest, len(words))
    return lookup, longest


_LOOKUP, _LONGEST_TAG_WORDS = _build_lookup()


def genre_families(tag: str) -> list[str]:
    """The dance genre families (of ``FAMILIES``) that a genre tag suggests, most specific first.

    ``"Hip-Hop"`` -> ``["hiphop", "pop"]``, ``"Salsa"`` -> ``["salsa", "pop"]``,
    ``"Bollywood"`` -> ``["indian"]``, ``"Latin Jazz"`` -> ``["salsa", "jazz", "pop"]``;
    an unknown tag (or not a string) gives ``[]``. Several genres may be given at
    once, separated by ``/ ; , |`` (as ``read_genre_tag`` joins them); ID3v1
    numbers (``"(17)"``, ``"17"``) are read as their genre names.
    """
    if not isinstance(tag, str):
        return []
    tag = re.sub(r"\((\d{1,3})\)", lambda m: f";{_numeric_genre(m.group(0)) or ''};", tag[:_MAX_TAG_CHARS])
    found: list[str] = []
    for part in re.split(r"[/;,|\x00\n]+", tag):
        part = _numeric_genre(part) or part
        words = _words(part)
        i = 0
        while i < len(words):
            for n in range(min(_LONGEST_TAG_WORDS, len(words) - i), 0, -1):
                families = _LOOKUP.get("".join(words[i:i + n]))
                if families is not None:
                    found.extend(f for f in families if f not in found)
                    i += n
                    break
            else:
                i += 1
    # "pop" is the catch-all: anything more specific goes before it.
    return [f for f in found if f != "pop"] + [f for f in found if f == "pop"]


# ---------------------------------------------------------------------------
# ID3v1 numeric genres
# ---------------------------------------------------------------------------

# The 80 genres of the original ID3v1 list; mutagen's (with Winamp's extensions) is used when installed.
_ID3V1_GENRES = (
    "Blues", "Classic Rock", "Country", "Dance", "Disco", "Funk", "Grunge", "Hip-Hop", "Jazz", "Metal",
    "New Age", "Oldies", "Other", "Pop", "R&B", "Rap", "Reggae", "Rock", "Techno", "Industrial",
    "Alternative", "Ska", "Death Metal", "Pranks", "Soundtrack", "Euro-Techno", "Ambient", "Trip-Hop",
    "Vocal", "Jazz+Funk", "Fusion", "Trance", "Classical", "Instrumental", "Acid", "House", "Game",
    "Sound Clip", "Gospel", "Noise", "Alt. Rock", "Bass", "Soul", "Punk", "Space", "Meditative",
    "Instrumental Pop", "Instrumental Rock", "Ethnic", "Gothic", "Darkwave", "Techno-Industrial",
    "Electronic", "Pop-Folk", "Eurodance", "Dream", "Southern Rock", "Comedy", "Cult", "Gangsta Rap",
    "Top 40", "Christian Rap", "Pop/Funk", "Jungle", "Native American", "Cabaret", "New Wave",
    "Psychedelic", "Rave", "Showtunes", "Trailer", "Lo-Fi", "Tribal", "Acid Punk", "Acid Jazz", "Polka",
    "Retro", "Musical", "Rock & Roll", "Hard Rock",
)
_GENRES: tuple[str, ...] = tuple(TCON.GENRES) if mutagen is not None else _ID3V1_GENRES


def _numeric_genre(value: str) -> str | None:
    """The genre name of an ID3v1 number, ``"17"`` or ``"(17)"`` -> ``"Rock"``; None otherwise."""
    match = re.fullmatch(r"\s*(\(\s*)?(\d{1,3})(?(1)\s*\))\s*", value)
    if match is None:
        return None
    index = int(match.group(2))
    return _GENRES[index] if index < len(_GENRES) else None


def _clean(values: Iterable[object]) -> str | None:
    """Genre values -> one tag: names for numbers, blanks and "Unknown" dropped, "; "-joined."""
    genres: list[str] = []
    for value in values:
        for text in str(value).split("\x00"):
            text = text.strip()
            text = _numeric_genre(text) or text
            if text and text.casefold() != "unknown" and text not in genres:
                genres.append(text)
    return "; ".join(genres) if genres else None


# ---------------------------------------------------------------------------
# Reading the tag
# ---------------------------------------------------------------------------

FFPROBE_TIMEOUT_S = 10.0
# A RIFF INFO list larger than this is not a tag list.
_MAX_INFO_BYTES = 1 << 20
_MAX_RIFF_CHUNKS = 4096
# The demuxers ffprobe may use: audio containers only (no playlists, concat scripts or image sequences).
_FFPROBE_FORMATS = ",".join((
    "mp3", "ogg", "flac", "mov", "wav", "w64", "aiff", "matroska", "asf", "wv", "ape", "mpc", "mpc8",
    "tta", "dsf", "caf", "aac", "ac3", "eac3", "dts", "truehd", "tak", "au", "amr", "mp2",
))
_GENRE_KEYS = {"genre", "tcon", "\xa9gen", "wm/genre", "ignr"}


def read_genre_tag(path: str | os.PathLike, *, timeout: float = FFPROBE_TIMEOUT_S) -> str | None:
    """The genre tag of the audio file at ``path``, or None when it has none or cannot be read.

    Several genres come back joined by ``"; "`` (``genre_families`` reads them all).
    Never raises for a tag problem; ``timeout`` bounds the ffprobe fallback.
    """
    try:
        fileobj = _open_regular(path)
    except (OSError, TypeError, ValueError):
        return None
    with fileobj:
        try:
            return _read_genre(fileobj, timeout)
        except Exception:  # a broken tag must not stop the dance
            return None


def _open_regular(path: str | os.PathLike) -> BinaryIO:
    """Open ``path`` for reading only when it is itself a regular file (not a link, FIFO or device)."""
    name = os.fspath(path)
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    if not hasattr(os, "O_NOFOLLOW") and os.path.islink(name):
        raise OSError(f"{name!r} is a symbolic link")
    fd = os.open(name, flags)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(f"{name!r} is not a regular file")
        raw = io.FileIO(fd, "rb", closefd=True)
    except BaseException:
        os.close(fd)
        raise
    try:
        raw.name = os.fsdecode(name)  # mutagen scores a format partly by the file's extension
    except (AttributeError, TypeError):
        pass
    return io.BufferedReader(raw)


def _read_genre(fileobj: BinaryIO, timeout: float) -> str | None:
    if mutagen is not None:
        audio = None
        try:
            audio = mutagen.File(fileobj)
        except Exception:
            audio = None
        if audio is not None:
            genre = _clean(_mutagen_genres(audio.tags))
            if genre is None and isinstance(audio, WAVE):
                genre = _riff_info_genre(fileobj)
            return genre
    genre = _riff_info_genre(fileobj)
    if genre is not None:
        return genre
    return _ffprobe_genre(fileobj, timeout)


def _mutagen_genres(tags) -> list[object]:
    if tags is None:
        return []
    if isinstance(tags, ID3):  # mp3, and the id3 chunk of WAV and AIFF; ID3v1 is read into TCON too
        return [genre for frame in tags.getall("TCON") for genre in frame.genres]
    if isinstance(tags, MP4Tags):  # mutagen turns the numeric gnre atom into a ©gen name
        return list(tags.get("\xa9gen", []))
    genres: list[object] = []  # Vorbis comments, APEv2, ASF...
    for key in list(tags.keys()):
        if isinstance(key, str) and key.casefold() in _GENRE_KEYS:
            value = tags[key]
            genres.extend(value if isinstance(value, list) else [value])
    return genres


def _riff_info_genre(fileobj: BinaryIO) -> str | None:
    """IGNR of a WAV file's ``LIST``/``INFO`` chunk, or None."""
    fileobj.seek(0)
    header = fileobj.read(12)
    if len(header) < 12 or header[:4] != b"RIFF" or header[8:12] != b"WAVE":
        return None
    for _ in range(_MAX_RIFF_CHUNKS):
        head = fileobj.read(8)
        if len(head) < 8:
            return None
        chunk_id, size = head[:4], struct.unpack("<I", head[4:])[0]
        if chunk_id == b"LIST" and 4 <= size <= _MAX_INFO_BYTES:
            body = fileobj.read(size)
            if body[:4] == b"INFO":
                genre = _info_list_genre(body[4:])
                if genre is not None:
                    return genre
            fileobj.seek(size & 1, io.SEEK_CUR)
        else:
            fileobj.seek(size + (size & 1), io.SEEK_CUR)
    return None


def _info_list_genre(body: bytes) -> str | None:
    pos = 0
    while pos + 8 <= len(body):
        sub_id, size = body[pos:pos + 4], struct.unpack("<I", body[pos + 4:pos + 8])[0]
        if pos + 8 + size > len(body):  # a sub-chunk running past its list: not a tag list
            return None
        value = body[pos + 8:pos + 8 + size]
        if sub_id == b"IGNR":
            value = value.split(b"\x00", 1)[0]
            try:
                text = value.decode("utf-8")
            except UnicodeDecodeError:
                text = value.decode("latin-1")
            return _clean([text])
        pos += 8 + size + (size & 1)
    return None


def _ffprobe_genre(fileobj: BinaryIO, timeout: float) -> str | None:
    exe = shutil.which("ffprobe")
    if exe is None:
        return None
    fd = fileobj.fileno()
    # ffprobe reopens the very file checked above through its descriptor where /proc allows
    # (no race with a swapped path), else the absolute path; either behind "file:", never a URL.
    if os.path.isdir("/proc/self/fd"):
        source, pass_fds = f"/proc/self/fd/{fd}", (fd,)
    else:  # pragma: no cover - not Linux
        source, pass_fds = os.path.abspath(os.fsdecode(fileobj.name)), ()
    command = [exe, "-v", "error", "-protocol_whitelist", "file", "-format_whitelist", _FFPROBE_FORMATS,
               "-show_entries", "format_tags=genre:stream_tags=genre", "-of", "json", "file:" + source]
    try:
        result = subprocess.run(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, timeout=timeout, pass_fds=pass_fds, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    if result.returncode != 0:
        return None
    try:
        report = json.loads(result.stdout)
    except ValueError:
        return None
    sections = [report.get("format")] + list(report.get("streams") or [])
    values = [value for section in sections if isinstance(section, dict)
              for key, value in (section.get("tags") or {}).items()
              if isinstance(key, str) and key.casefold() == "genre"]
    return _clean(values)
