"""Audio loading (``dancesynth.io.audio.load_audio``) of mutated WAV, AIFF, CAF, FLAC, Ogg and MP3 files.

Mutates: 5-second excerpts of a bundled song made with ffmpeg (WAV 16-bit mono
and stereo, WAV float, AIFF, CAF, FLAC, Ogg Vorbis, MP3, and M4A for the ffmpeg path), by
setting header fields to hostile values (channel counts from 0 to 65535, sample
rates 0 / huge, bit depths, data sizes; the Ogg page CRC is recomputed so the
change reaches the decoder) and by generic byte mutations (flips, cuts,
truncation, junk before or after).

Sane: mono float32 samples, all finite, at the requested 22050 Hz, as long as
the 4 s-15 min limits allow.
"""

from __future__ import annotations

import random
import struct
import subprocess
from pathlib import Path

import numpy as np

from .harness import Case, Insane, Target, mutate_bytes, rng_for, write_file

REPO = Path(__file__).resolve().parents[2]
SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"
# name -> ffmpeg output options (8 kHz keeps the seeds small and decoding fast)
SEEDS = {
    "mono.wav": ["-ac", "1", "-ar", "8000", "-c:a", "pcm_s16le"],
    "stereo.wav": ["-ac", "2", "-ar", "8000", "-c:a", "pcm_s16le"],
    "float.wav": ["-ac", "1", "-ar", "8000", "-c:a", "pcm_f32le"],
    "song.flac": ["-ac", "2", "-ar", "8000"],
    "song.ogg": ["-ac", "2", "-ar", "8000", "-c:a", "libvorbis", "-q:a", "0"],
    "song.mp3": ["-ac", "1", "-ar", "8000", "-c:a", "libmp3lame", "-b:a", "16k"],
    "song.m4a": ["-ac", "1", "-ar", "8000", "-c:a", "aac", "-b:a", "16k"],
    "song.aiff": ["-ac", "1", "-ar", "8000", "-c:a", "pcm_s16be"],
    "song.caf": ["-ac", "1", "-ar", "8000", "-c:a", "pcm_s16be"],
}
SR = 22050
CHANNELS = [0, 1, 2, 3, 8, 255, 256, 257, 300, 1024, 4096, 32767, 65535]
RATES = [0, 1, 7, 8000, 44100, 192000, 384000, 10 ** 6, 2 ** 31 - 1, 2 ** 32 - 1]


class AudioTarget(Target):
    name = "audio"
    mutates = "header fields and bytes of WAV/FLAC/Ogg/MP3/M4A excerpts made with ffmpeg"
    sane = "mono float32, finite, 22050 Hz, 4 s to 15 min long"

    def prepare(self, workdir: Path) -> None:
        seeds = workdir / "audio_seeds"
        seeds.mkdir(parents=True, exist_ok=True)
        for name, opts in SEEDS.items():
            out = seeds / name
            if not out.is_file():
                part = out.with_name("part-" + name)
                subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-y", "-ss", "20", "-t", "5", "-i", str(SONG),
                                "-map", "0:a", "-map_metadata", "-1", "-fflags", "+bitexact", *opts, str(part)],
                               check=True)
                part.rename(out)

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        seeds = {p.name: p.read_bytes() for p in sorted((workdir / "audio_seeds").iterdir())}
        names = sorted(seeds)
        rng = rng_for(seed, "audio")
        out = []
        for i in range(n):
            name = names[i % len(names)]
            data, how = _mutate(rng, name, seeds[name])
            out.append(Case(f"{name}:{how}", (Path(name).suffix, data)))
        return out

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.io.audio import load_audio

        suffix, data = case.data
        path = workdir / f"case{suffix}"
        path.write_bytes(data)
        y, sr = load_audio(path, sr=SR)
        if sr != SR or y.ndim != 1 or y.dtype != np.float32:
            raise Insane(f"wrong form: {y.dtype} {y.shape} at {sr} Hz")
        if not np.all(np.isfinite(y)):
            raise Insane("non-finite samples")
        if not 3.5 * SR <= len(y) <= 901 * SR:
            raise Insane(f"length {len(y) / SR:.2f} s is outside the 4 s-15 min limits")

    def save(self, case: Case, folder: Path, stem: str) -> Path:
        suffix, data = case.data
        return write_file(folder, f"{stem}{suffix}", data)


def _mutate(rng: random.Random, name: str, data: bytes) -> tuple[bytes, str]:
    r = rng.random()
    if r < 0.45:
        header = {".wav": _wav_field, ".flac": _flac_field, ".ogg": _ogg_field, ".aiff": _aiff_field,
                  ".caf": _caf_field}.get(Path(name).suffix)
        if header is not None:
            return header(rng, bytearray(data))
    if r < 0.55:
        cut = rng.randrange(len(data))
        return data[:cut], f"truncate@{cut}"
    return mutate_bytes(rng, data)


def _wav_field(rng: random.Random, buf: bytearray) -> tuple[bytes, str]:
    """Set one field of the fmt or data chunk (found by walking the RIFF chunks)."""
    chunks, pos = {}, 12
    while pos + 8 <= len(buf):
        cid, size = bytes(buf[pos:pos + 4]), struct.unpack("<I", buf[pos + 4:pos + 8])[0]
        chunks[cid] = pos
        pos += 8 + size + (size & 1)
    fmt, dat = chunks[b"fmt "] + 8, chunks[b"data"] + 4
    field, (at, fmt_code, values) = rng.choice(list({
        "format": (fmt, "<H", [0, 2, 3, 0xFFFE, 0xFFFF]),
        "channels": (fmt + 2, "<H", CHANNELS),
        "rate": (fmt + 4, "<I", RATES),
        "byte_rate": (fmt + 8, "<I", [0, 1, 2 ** 32 - 1]),
        "block_align": (fmt + 12, "<H", [0, 1, 3, 65535]),
        "bits": (fmt + 14, "<H", [0, 1, 4, 8, 12, 24, 32, 64, 65535]),
        "data_size": (dat, "<I", [0, 1, 2, 2 ** 31, 2 ** 32 - 1, len(buf)]),
        "riff_size": (4, "<I", [0, 4, 2 ** 32 - 1]),
    }.items()))
    value = rng.choice(values)
    struct.pack_into(fmt_code, buf, at, value)
    return bytes(buf), f"{field}={value}"


def _aiff_field(rng: random.Random, buf: bytearray) -> tuple[bytes, str]:
    """The COMM chunk's channel count (big-endian 16 bits) or frame count (32 bits)."""
    comm = buf.index(b"COMM") + 8
    field, at, code = rng.choice([("channels", comm, ">H"), ("frames", comm + 2, ">I")])
    value = rng.choice(CHANNELS if field == "channels" else [0, 1, 2 ** 31, 2 ** 32 - 1])
    struct.pack_into(code, buf, at, value)
    return bytes(buf), f"aiff {field}={value}"


def _caf_field(rng: random.Random, buf: bytearray) -> tuple[bytes, str]:
    """The desc chunk: sample rate (float64), then bytes/frames per packet, channels per frame, bits (32 bits)."""
    desc = buf.index(b"desc") + 12
    field, at, code, values = rng.choice([("channels", desc + 24, ">I", CHANNELS + [2 ** 32 - 1]),
                                          ("rate", desc, ">d", [0.0, -1.0, 1e12, float("nan")]),
                                          ("bits", desc + 28, ">I", [0, 1, 64, 2 ** 32 - 1])])
    value = rng.choice(values)
    struct.pack_into(code, buf, at, value)
    return bytes(buf), f"caf {field}={value}"


def _flac_field(rng: random.Random, buf: bytearray) -> tuple[bytes, str]:
    """STREAMINFO (the first metadata block): 20-bit rate, 3-bit channels-1, 5-bit bits-1, 36-bit length."""
    si = 8  # "fLaC" + the block header
    word = int.from_bytes(buf[si + 10:si + 18], "big")
    field = rng.choice(["rate", "channels", "bits", "samples", "blocksize"])
    if field == "rate":
        v = rng.choice([0, 1, 8000, 655350, 2 ** 20 - 1])
        word = (word & ~(0xFFFFF << 44)) | (v << 44)
    elif field == "channels":
        v = rng.randrange(8)
        word = (word & ~(0x7 << 41)) | (v << 41)
    elif field == "bits":
        v = rng.randrange(32)
        word = (word & ~(0x1F << 36)) | (v << 36)
    elif field == "samples":
        v = rng.choice([0, 1, 2 ** 36 - 1, 8000 * 3600])
        word = (word & ~(2 ** 36 - 1)) | v
    else:
        v = rng.choice([0, 1, 16, 65535])
        struct.pack_into(">HH", buf, si, v, v)
    if field != "blocksize":
        buf[si + 10:si + 18] = word.to_bytes(8, "big")
    return bytes(buf), f"flac_{field}={v}"


def _ogg_crc(page: bytes) -> int:
    crc = 0
    for byte in page:
        crc ^= byte << 24
        for _ in range(8):
            crc = ((crc << 1) ^ 0x04C11DB7) & 0xFFFFFFFF if crc & 0x80000000 else (crc << 1) & 0xFFFFFFFF
    return crc


def _ogg_field(rng: random.Random, buf: bytearray) -> tuple[bytes, str]:
    """A field of the Vorbis identification header or of a page header, with the page CRC fixed."""
    pages, pos = [], 0
    while pos + 27 <= len(buf) and buf[pos:pos + 4] == b"OggS":
        n_seg = buf[pos + 26]
        size = 27 + n_seg + sum(buf[pos + 27:pos + 27 + n_seg])
        pages.append((pos, size))
        pos += size
    first, first_size = pages[0]
    ident = first + 27 + buf[first + 26]  # "\x01vorbis", version, channels, rate, ...
    choice = rng.choice(["channels", "rate", "granule", "flags", "version"])
    if choice == "channels":
        v = rng.choice([0, 1, 2, 8, 255])
        buf[ident + 11] = v
        page = (first, first_size)
    elif choice == "rate":
        v = rng.choice(RATES)
        struct.pack_into("<I", buf, ident + 12, v)
        page = (first, first_size)
    elif choice == "version":
        v = rng.choice([1, 2 ** 32 - 1])
        struct.pack_into("<I", buf, ident + 7, v)
        page = (first, first_size)
    else:
        page = rng.choice(pages)
        if choice == "granule":
            v = rng.choice([0, 2 ** 63 - 1, 2 ** 64 - 1, 2 ** 40])
            struct.pack_into("<Q", buf, page[0] + 6, v)
        else:
            v = rng.choice([0, 1, 2, 4, 6, 0xFF])
            buf[page[0] + 5] = v
    at, size = page
    struct.pack_into("<I", buf, at + 22, 0)
    struct.pack_into("<I", buf, at + 22, _ogg_crc(bytes(buf[at:at + size])))
    return bytes(buf), f"ogg_{choice}={v}"


TARGET = AudioTarget()
