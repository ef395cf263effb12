"""A song's form: sections that repeat (verse, chorus, ...) and the phrases within them.

Everything is counted in bars, from the beats and downbeats the analysis already found:

1. Each beat gets the mean of its frames' chroma (harmony and melody) and MFCCs with
   loudness (timbre, instrumentation); a bar is its beats' features side by side, so two
   bars are alike when they play the same notes in the same order.
2. The bars' self-similarity matrix (cosine, chroma and timbre weighted) has a block on
   its diagonal for each section and a stripe off it for each repeat.
3. Boundaries are the peaks of Foote's checkerboard novelty along the diagonal (a kernel
   of ``KERNEL_BARS`` bars each side), at least ``MIN_SECTION_BARS`` apart; sections
   therefore start on downbeats.
4. Labels: a section takes the label of the earlier section it matches bar by bar (the
   mean similarity along the aligned diagonal) above ``SAME_SECTION``; else a new one.
   Names follow the labels: the loudest label heard more than once is the chorus, other
   repeated ones verses, a lone first or last short section the intro or outro, any
   other lone section a bridge.

Phrases are 4- and 8-bar groups counted from each section's first bar. ``analyze_music(...,
structure=True)`` runs this on the samples it decoded.
"""

from __future__ import annotations

import numpy as np

from ..types import Phrase, Section, SongStructure
from .intensity import rms_db

HOP = 512
KERNEL_BARS = 4          # the novelty kernel's half width: sections shorter than this blur into their neighbours
MIN_SECTION_BARS = 4     # no two boundaries closer than this
NOVELTY_Z = 1.0          # a boundary's novelty, above the song's median, in MADs
SAME_SECTION = 0.6       # aligned bar similarity above which a section repeats an earlier one
CHROMA_WEIGHT = 0.6      # of the bar similarity; the rest is timbre and loudness
PHRASE_BARS = (4, 8)
GRID_BARS = 4            # sections start on 4-bar phrase lines from the first downbeat (1: anywhere)


def beat_features(samples: np.ndarray, sr: int, beat_times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(chroma (B, 12), timbre (B, 14))`` per beat interval (the last beat to the end of the audio)."""
    import librosa

    chroma = librosa.feature.chroma_stft(y=samples, sr=sr, hop_length=HOP)
    mfcc = librosa.feature.mfcc(y=samples, sr=sr, hop_length=HOP, n_mfcc=14)[1:]
    rms = librosa.feature.rms(y=samples, hop_length=HOP)
    loud = rms_db(rms) / 10.0
    n = chroma.shape[1]
    edges = np.clip(np.rint(np.r_[beat_times_s, len(samples) / sr] * sr / HOP).astype(np.int64), 0, n)
    edges = np.maximum.accumulate(edges)

    def mean_between(x):
        cum = np.concatenate([np.zeros((x.shape[0], 1)), np.cumsum(x, axis=1)], axis=1)
        width = np.maximum(np.diff(edges), 1)
        return ((cum[:, edges[1:]] - cum[:, edges[:-1]]) / width).T

    return mean_between(chroma), mean_between(np.vstack([mfcc, loud]))


def bar_similarity(chroma: np.ndarray, timbre: np.ndarray, bar_first_beat: np.ndarray,
                   beats_per_bar: int, *, ordered: bool = True) -> np.ndarray:
    """(N, N) cosine similarity of the bars starting at ``bar_first_beat``: chroma and timbre
    (z-scored over the song) of each of their beats in order (``ordered``: the same notes in the
    same order), or the timbre of the bar as a whole (its sound: instruments, loudness)."""
    timbre = (timbre - timbre.mean(axis=0)) / np.maximum(timbre.std(axis=0), 1e-9)
    chroma = chroma / np.maximum(chroma.max(axis=1, keepdims=True), 1e-9)
    chroma = chroma - chroma.mean(axis=0)
    idx = np.clip(bar_first_beat[:, None] + np.arange(beats_per_bar)[None, :], 0, len(chroma) - 1)

    def cosine(x):
        v = x[idx].reshape(len(idx), -1) if ordered else x[idx].mean(axis=1)
        v = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-9)
        return v @ v.T

    if not ordered:   # a bar's chord changes within a section: its sound is its timbre
        return cosine(timbre)
    return CHROMA_WEIGHT * cosine(chroma) + (1.0 - CHROMA_WEIGHT) * cosine(timbre)


def novelty(sim: np.ndarray, half: int = KERNEL_BARS) -> np.ndarray:
    """(N,) Foote's checkerboard novelty of a boundary before each bar (0 within ``half`` of the ends)."""
    n = len(sim)
    ax = np.arange(-half, half) + 0.5
    taper = np.exp(-0.5 * (ax / half) ** 2)
    kernel = np.sign(ax)[:, None] * np.sign(ax)[None, :] * taper[:, None] * taper[None, :]
    padded = np.pad(sim, half)
    out = np.zeros(n)
    for b in range(half, n - half + 1):   # nearer the ends the kernel would be half outside the song
        block = padded[b:b + 2 * half, b:b + 2 * half]
        out[b] = np.sum(kernel * block)   # alike within either side, unlike across the boundary
    return out


def boundaries(nov: np.ndarray, min_bars: int = MIN_SECTION_BARS, z: float = NOVELTY_Z,
               grid: int = GRID_BARS) -> list[int]:
    """The bars sections start at: 0 and the novelty's peaks ``z`` MADs above its median, strongest
    first, none within ``min_bars`` of another or of the ends. Sections come in phrases: a peak is
    moved to the ``grid``-bar line (counted from the first downbeat) within a bar of it, where the
    novelty over those three bars is highest (a held chord or a drum fill blurs where the change is)."""
    n = len(nov)
    med = np.median(nov[1:]) if n > 1 else 0.0
    mad = np.median(np.abs(nov[1:] - med)) if n > 1 else 0.0
    floor = med + z * max(mad, 1e-9)
    if grid > 1:
        lines = np.arange(grid, n, grid)
        near = np.max([nov[np.clip(lines + d, 0, n - 1)] for d in (-1, 0, 1)], axis=0)
        # a peak: no lower than the lines either side (one change blurs over the lines around it)
        peak = (near >= np.r_[-np.inf, near[:-1]]) & (near >= np.r_[near[1:], -np.inf])
        nov = np.zeros(n)
        nov[lines] = np.where(peak, near, 0.0)
    chosen = [0]
    for b in np.argsort(-nov):
        if nov[b] <= floor:
            break
        if b >= min_bars and n - b >= min_bars and all(abs(int(b) - c) >= min_bars for c in chosen):
            chosen.append(int(b))
    return sorted(chosen)


def section_labels(sim: np.ndarray, starts: list[int], same: float = SAME_SECTION) -> list[int]:
    """Per section (bars ``starts[k]`` to the next start): the index of its label, the first section's 0.
    A section repeats the earlier one whose bars it matches best, aligned from both starts, above ``same``."""
    ends = starts[1:] + [len(sim)]
    labels: list[int] = []
    for k, (a, b) in enumerate(zip(starts, ends)):
        best, best_label = same, -1
        for j in range(k):
            a2, b2 = starts[j], ends[j]
            m = min(b - a, b2 - a2)
            score = float(np.mean(sim[a + np.arange(m), a2 + np.arange(m)]))
            if score > best:
                best, best_label = score, labels[j]
        labels.append(best_label if best_label >= 0 else max(labels, default=-1) + 1)
    return labels


def _names(labels: list[int], bars: list[int], loudness: list[float]) -> list[str]:
    """verse / chorus / bridge / intro / outro for each section, from its label's repeats and loudness."""
    count = {lab: labels.count(lab) for lab in labels}
    repeated = sorted({lab for lab in labels if count[lab] > 1},
                      key=lambda lab: -np.mean([v for v, l2 in zip(loudness, labels) if l2 == lab]))
    names = []
    for k, lab in enumerate(labels):
        if count[lab] > 1:
            names.append("chorus" if lab == repeated[0] and len(repeated) > 1 else "verse")
        elif k == 0 and len(labels) > 1 and bars[k] < 8:
            names.append("intro")
        elif k == len(labels) - 1 and len(labels) > 1 and bars[k] < 8:
            names.append("outro")
        else:
            names.append("bridge")
    return names


def song_structure(samples: np.ndarray, sr: int, beat_times_s: np.ndarray, beat_in_bar: np.ndarray | None,
                   beats_per_bar: int | None, duration_s: float) -> SongStructure:
    """The song's sections and phrases (see the module's text). A song of fewer than
    ``2 * MIN_SECTION_BARS`` bars, or of unknown metre, is one section."""
    beat_times_s = np.asarray(beat_times_s, dtype=np.float64)
    first = np.flatnonzero(np.asarray(beat_in_bar) == 0) if beat_in_bar is not None else np.zeros(0, np.int64)
    n_bars = len(first)
    if beats_per_bar is None or not n_bars:
        return SongStructure((Section(0.0, float(duration_s), "A", "verse", 0, 0),), ())
    bar_s = np.r_[beat_times_s[first], duration_s]
    bar_s[0] = 0.0   # a pickup belongs to the first bar
    chroma, timbre = beat_features(samples, sr, beat_times_s)
    sim = bar_similarity(chroma, timbre, first, beats_per_bar)
    if n_bars < 2 * MIN_SECTION_BARS:
        return _structure([0], [0], [0.0], bar_s, n_bars, duration_s, sim, beat_times_s[first])
    starts = boundaries(novelty(bar_similarity(chroma, timbre, first, beats_per_bar, ordered=False)))
    labels = section_labels(sim, starts)
    loud = timbre[:, -1]
    ends = starts[1:] + [n_bars]
    loudness = [float(np.mean(loud[first[a]:first[b - 1] + beats_per_bar])) for a, b in zip(starts, ends)]
    return _structure(starts, labels, loudness, bar_s, n_bars, duration_s, sim, beat_times_s[first])


def _structure(starts, labels, loudness, bar_s, n_bars, duration_s, sim, downbeats_s) -> SongStructure:
    ends = list(starts[1:]) + [n_bars]
    bars = [b - a for a, b in zip(starts, ends)]
    names = _names(list(labels), bars, list(loudness))
    sections = tuple(Section(float(bar_s[a]), float(bar_s[b]) if b < n_bars else float(duration_s),
                             chr(ord("A") + lab) if lab < 26 else f"S{lab}", name, int(a), int(b - a))
                     for a, b, lab, name in zip(starts, ends, labels, names))
    phrases = tuple(Phrase(float(bar_s[a + k]), int(a + k), int(min(size, b - a - k)), size)
                    for size in PHRASE_BARS for a, b in zip(starts, ends) for k in range(0, b - a, size))
    return SongStructure(sections, phrases, tuple(float(t) for t in downbeats_s), sim)
