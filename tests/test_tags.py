"""The genre tag of a song file (dancesynth.music.tags): real files tagged by ffmpeg, read back."""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sys
import time

import pytest

from dancesynth.music import tags
from dancesynth.music.tags import FAMILIES, GENRE_TABLE, genre_families, read_genre_tag

needs_ffmpeg = pytest.mark.skipif(shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None,
                                  reason="needs ffmpeg and ffprobe")
needs_mutagen = pytest.mark.skipif(tags.mutagen is None, reason="needs mutagen")

FORMATS = ["mp3", "ogg", "opus", "flac", "m4a", "wav"]


def _ffmpeg(out, *options: str) -> str:
    subprocess.run(["ffmpeg", "-nostdin", "-y", "-loglevel", "error", "-f", "lavfi", "-i", "sine=f=440:d=1",
                    *options, str(out)], check=True, timeout=60)
    return str(out)


def tagged(tmp_path, ext: str, genre: str | None = "Hip-Hop", name: str = "song") -> str:
    """A one-second sine tone as ``name.ext``, with a genre tag unless ``genre`` is None."""
    options = ["-metadata", f"genre={genre}"] if genre is not None else ["-map_metadata", "-1"]
    return _ffmpeg(tmp_path / f"{name}.{ext}", *options)


@pytest.fixture(params=["mutagen", "ffprobe"])
def reader(request, monkeypatch):
    """Run a test with mutagen (when installed) and with the ffprobe fallback mutagen's absence leaves."""
    if request.param == "mutagen" and tags.mutagen is None:
        pytest.skip("mutagen is not installed")
    if request.param == "ffprobe":
        monkeypatch.setattr(tags, "mutagen", None)
    return request.param


# -- reading the tag ---------------------------------------------------------------------------------------


@needs_ffmpeg
@pytest.mark.parametrize("ext", FORMATS)
def test_reads_the_genre_of_every_format(tmp_path, ext, reader):
    assert read_genre_tag(tagged(tmp_path, ext)) == "Hip-Hop"


@needs_ffmpeg
@pytest.mark.parametrize("ext", FORMATS)
def test_a_file_without_a_genre_gives_none(tmp_path, ext, reader):
    assert read_genre_tag(tagged(tmp_path, ext, genre=None)) is None


@needs_ffmpeg
def test_accepts_path_objects_and_non_ascii_genres(tmp_path, reader):
    path = tagged(tmp_path, "flac", genre="Música Latina")
    assert read_genre_tag(tmp_path / os.path.basename(path)) == "Música Latina"


@needs_ffmpeg
@pytest.mark.parametrize("ext", ["mp3", "flac"])
@pytest.mark.parametrize("genre", ["(17)", "17"])
def test_id3v1_numbers_in_a_genre_tag_are_read_as_names(tmp_path, ext, genre, reader):
    assert read_genre_tag(tagged(tmp_path, ext, genre=genre)) == "Rock"


def _id3v1(genre: int) -> bytes:
    tag = (b"TAG" + b"Title".ljust(30, b"\0") + b"Artist".ljust(30, b"\0") + b"Album".ljust(30, b"\0")
           + b"1999" + b"comment".ljust(30, b"\0") + bytes([genre]))
    assert len(tag) == 128
    return tag


@needs_ffmpeg
def test_an_id3v1_tag_genre_byte(tmp_path, reader):
    path = _ffmpeg(tmp_path / "v1.mp3", "-map_metadata", "-1", "-id3v2_version", "0", "-write_xing", "0")
    assert read_genre_tag(path) is None
    with open(path, "ab") as f:
        f.write(_id3v1(17))
    assert read_genre_tag(path) == "Rock"


def _replace_mp4_atom(data: bytes, path: list[bytes], new: bytes) -> bytes:
    """``data`` with the atom at ``path`` replaced by ``new``, the sizes of its parents fixed."""

    def walk(buf: bytes, start: int, end: int, depth: int) -> tuple[bytes, int]:
        pos = start
        while pos + 8 <= end:
            size, name = struct.unpack(">I4s", buf[pos:pos + 8])
            if name == path[depth]:
                if depth == len(path) - 1:
                    return buf[:pos] + new + buf[pos + size:], len(new) - size
                child = pos + 8 + (4 if name == b"meta" else 0)  # meta is a full atom
                buf, delta = walk(buf, child, pos + size, depth + 1)
                return buf[:pos] + struct.pack(">I", size + delta) + buf[pos + 4:], delta
            pos += size
        raise AssertionError(f"no {path[depth]!r} atom")

    return walk(data, 0, len(data), 0)[0]


@needs_ffmpeg
def test_the_numeric_gnre_atom_of_mp4(tmp_path, reader):
    path = tagged(tmp_path, "m4a", genre="Placeholder")
    with open(path, "rb") as f:
        data = f.read()
    assert data.index(b"mdat") < data.index(b"moov")  # moov last: resizing it moves no sample offsets
    value = struct.pack(">I4sI4sH", 18, b"data", 0, b"\0\0\0\0", 18)  # gnre numbers are ID3v1's + 1
    gnre = struct.pack(">I4s", 8 + len(value), b"gnre") + value
    with open(path, "wb") as f:
        f.write(_replace_mp4_atom(data, [b"moov", b"udta", b"meta", b"ilst", b"\xa9gen"], gnre))
    assert read_genre_tag(path) == "Rock"


@needs_ffmpeg
def test_wav_riff_info_ignr(tmp_path, reader):
    path = tagged(tmp_path, "wav", genre="Bollywood")
    with open(path, "rb") as f:
        assert b"IGNR" in f.read(4096)
    assert read_genre_tag(path) == "Bollywood"


@needs_ffmpeg
@needs_mutagen
def test_wav_id3_chunk(tmp_path, reader):
    from mutagen.id3 import TCON
    from mutagen.wave import WAVE

    path = _ffmpeg(tmp_path / "id3.wav", "-map_metadata", "-1", "-fflags", "+bitexact")
    assert read_genre_tag(path) is None
    wave = WAVE(path)
    wave.add_tags()
    wave.tags.add(TCON(encoding=3, text=["Salsa"]))
    wave.save()
    assert read_genre_tag(path) == "Salsa"


@needs_ffmpeg
@needs_mutagen
def test_several_genres_are_joined(tmp_path):
    from mutagen.flac import FLAC

    path = tagged(tmp_path, "flac", genre=None)
    flac = FLAC(path)
    flac["genre"] = ["Latin", "Jazz", "Latin", ""]
    flac.save()
    assert read_genre_tag(path) == "Latin; Jazz"
    assert genre_families(read_genre_tag(path)) == ["salsa", "jazz", "pop"]


# -- never raising -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("content", [b"", b"not audio at all\n" * 50, os.urandom(4096),
                                     b"ID3\x04\x00\x00\x7f\x7f\x7f\x7f" + os.urandom(512),
                                     b"RIFF\xff\xff\xff\xffWAVELIST\xff\xff\xff\x7fINFO",
                                     b"RIFF\x40\x00\x00\x00WAVELIST\x10\x00\x00\x00INFOIGNR\xff\xff\xff\xffab",
                                     b"fLaC\x00\x00\x00\x22" + os.urandom(64), b"OggS" + os.urandom(200)])
@pytest.mark.parametrize("ext", FORMATS + ["txt"])
def test_garbage_gives_none(tmp_path, content, ext, reader):
    path = tmp_path / f"garbage.{ext}"
    path.write_bytes(content)
    assert read_genre_tag(path) is None


@needs_ffmpeg
def test_a_truncated_file_gives_none_or_its_tag(tmp_path, reader):
    for ext in FORMATS:
        path = tagged(tmp_path, ext)
        with open(path, "rb") as f:
            head = f.read(200)
        with open(path, "wb") as f:
            f.write(head)
        assert read_genre_tag(path) in (None, "Hip-Hop")


def test_what_is_not_a_readable_regular_file_gives_none(tmp_path):
    assert read_genre_tag(tmp_path / "missing.mp3") is None
    assert read_genre_tag(tmp_path) is None
    assert read_genre_tag(None) is None  # type: ignore[arg-type]
    assert read_genre_tag(3) is None  # type: ignore[arg-type]
    assert read_genre_tag("bad\0name.mp3") is None


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_gives_none_without_blocking(tmp_path):
    fifo = tmp_path / "song.mp3"
    os.mkfifo(fifo)
    start = time.monotonic()
    assert read_genre_tag(fifo) is None
    assert time.monotonic() - start < 5


@needs_ffmpeg
@pytest.mark.skipif(sys.platform == "win32", reason="symbolic links")
def test_symbolic_links_are_not_followed(tmp_path, reader):
    target = tagged(tmp_path, "mp3")
    link = tmp_path / "link.mp3"
    link.symlink_to(target)
    assert read_genre_tag(target) == "Hip-Hop"
    assert read_genre_tag(link) is None


@needs_ffmpeg
def test_ffprobe_opens_no_playlist_or_concat_script(tmp_path, monkeypatch):
    monkeypatch.setattr(tags, "mutagen", None)
    tagged(tmp_path, "mp3")
    (tmp_path / "list.m3u8").write_text("#EXTM3U\n#EXT-X-TARGETDURATION:1\n#EXTINF:1.0,\nsong.mp3\n#EXT-X-ENDLIST\n")
    (tmp_path / "list.ffconcat").write_text("ffconcat version 1.0\nfile 'song.mp3'\n")
    assert read_genre_tag(tmp_path / "list.m3u8") is None
    assert read_genre_tag(tmp_path / "list.ffconcat") is None


@pytest.mark.skipif(sys.platform == "win32", reason="a shell script stands in for ffprobe")
def test_a_hanging_ffprobe_is_cut_off(tmp_path, monkeypatch):
    fake = tmp_path / "ffprobe"
    fake.write_text("#!/bin/sh\nexec sleep 30\n")
    fake.chmod(0o755)
    monkeypatch.setattr(tags, "mutagen", None)
    monkeypatch.setattr(tags.shutil, "which", lambda name: str(fake))
    song = tmp_path / "song.mp3"
    song.write_bytes(os.urandom(1024))
    start = time.monotonic()
    assert read_genre_tag(song, timeout=0.5) is None
    assert time.monotonic() - start < 10


def test_no_ffprobe_gives_none(tmp_path, monkeypatch):
    monkeypatch.setattr(tags, "mutagen", None)
    monkeypatch.setattr(tags.shutil, "which", lambda name: None)
    song = tmp_path / "song.mp3"
    song.write_bytes(os.urandom(1024))
    assert read_genre_tag(song) is None


# -- genre families ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("tag, families", [
    ("Hip-Hop", ["hiphop", "pop"]), ("hip hop", ["hiphop", "pop"]), ("HIPHOP", ["hiphop", "pop"]),
    ("Rap", ["hiphop", "pop"]), ("Trap", ["hiphop", "pop"]), ("Gangsta Rap", ["hiphop", "pop"]),
    ("R&B", ["pop"]), ("RnB", ["pop"]), ("Rhythm & Blues", ["pop"]), ("rhythm and blues", ["pop"]),
    ("Pop", ["pop"]), ("K-Pop", ["pop"]), ("kpop", ["pop"]), ("J-Pop", ["pop"]), ("Dance-Pop", ["pop"]),
    ("Dance", ["pop"]), ("Electronic", ["pop"]), ("EDM", ["pop"]), ("House", ["pop"]),
    ("Deep House", ["pop"]), ("Disco", ["pop"]), ("Funk", ["pop"]), ("Rock", ["pop"]),
    ("Latin", ["salsa", "pop"]), ("Salsa", ["salsa", "pop"]), ("Mambo", ["salsa", "pop"]),
    ("Cha-Cha", ["salsa", "pop"]), ("cha cha cha", ["salsa", "pop"]), ("Bachata", ["salsa", "pop"]),
    ("Merengue", ["salsa", "pop"]), ("Reggaetón", ["salsa", "pop"]),
    ("Indian", ["indian"]), ("Bollywood", ["indian"]), ("Bhangra", ["indian"]), ("World", ["indian"]),
    ("Jazz", ["jazz"]), ("Swing", ["jazz"]), ("Ragtime", ["jazz"]), ("Blues", ["jazz"]),
    ("Big Band", ["jazz"]), ("Broadway", ["jazz"]), ("Show Tunes", ["jazz"]), ("Showtunes", ["jazz"]),
    ("Rock 'n' Roll", ["jazz", "pop"]), ("Rock & Roll", ["jazz", "pop"]),
    ("Classical", ["classical"]), ("Ballet", ["classical"]), ("Waltz", ["classical"]),
    ("Orchestral", ["classical"]), ("Soundtrack", ["classical"]),
    # several genres, most specific first, "pop" last
    ("Latin Pop", ["salsa", "pop"]), ("Pop Rap", ["hiphop", "pop"]), ("Latin Jazz", ["salsa", "jazz", "pop"]),
    ("Hip-Hop/Rap", ["hiphop", "pop"]), ("Alternative Hip Hop", ["hiphop", "pop"]),
    ("Jazz; Classical", ["jazz", "classical"]), ("Electronic, Dance", ["pop"]),
    # ID3v1 numbers
    ("(17)", ["pop"]), ("7", ["hiphop", "pop"]), ("(32)Classical", ["classical"]),
])
def test_genre_families(tag, families):
    assert genre_families(tag) == families


@pytest.mark.parametrize("tag", ["", "   ", "Country", "Metalcore?", "Classic", "Hop", "hip", "(999)", "Unknown"])
def test_unknown_tags_have_no_family(tag):
    assert genre_families(tag) == []


def test_what_is_not_a_tag_has_no_family():
    assert genre_families(None) == []  # type: ignore[arg-type]
    assert genre_families(17) == []  # type: ignore[arg-type]
    assert genre_families("Country " * 10_000) == []


def test_every_table_row_maps_onto_its_families():
    for names, families in GENRE_TABLE:
        assert set(families) <= set(FAMILIES)
        for name in names:
            found = genre_families(name)
            assert set(found) == set(families), name
            assert found[-1] == "pop" or "pop" not in found, name


@needs_ffmpeg
def test_a_read_tag_maps_onto_families(tmp_path):
    assert genre_families(read_genre_tag(tagged(tmp_path, "ogg", genre="Bachata"))) == ["salsa", "pop"]
