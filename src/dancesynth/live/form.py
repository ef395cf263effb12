"""The song's form heard live: a repeat is recognised from the music so far, and danced again.

Each beat the tracker gives gets the chroma and timbre of its interval (``music.structure.
beat_features``) from the last ``BUFFER_S`` of audio; a bar is its beats' features side by
side, compared with every bar heard before it as the offline analysis compares them (chroma
in order and timbre, each normalised over the bars heard so far; ``music.structure.
bar_similarity``). Only what was heard is used, so a repeat is found once it has been heard:

- when the two bars just completed sound like two consecutive earlier bars (the mean of the
  aligned similarities at least ``music.structure.SAME_SECTION``), the music is taken to
  repeat from there on: each following beat replays the beat at the same place that many
  bars back, as long as each completed bar still sounds like its pair (``STAY``);
- section boundaries are the offline checkerboard novelty's peaks, each confirmed once the
  kernel's ``KERNEL_BARS`` bars after it have been heard (about four bars late, placed on
  the bar where the music changed).

``LiveForm.plan`` is a ``engines.form.FormPlan`` over every beat so far, which the streaming
engine follows as it follows the offline one.
"""

from __future__ import annotations

import numpy as np

from ..engines.form import PHRASE_BARS, FormPlan, check_repeat
from ..music.structure import (KERNEL_BARS, MIN_SECTION_BARS, SAME_SECTION, bar_similarity, beat_features,
                               boundaries, novelty)
from .ring import Ring

BUFFER_S = 30.0        # audio kept for the beats' features (beats are given a few seconds late)
MAX_BARS = 256         # the bars compared (about 8 minutes at 120 bpm): memory and time stay bounded
STAY = 0.5             # a replay goes on while each completed bar sounds at least this like its pair
MIN_LAG_BARS = 2       # a repeat is at least this many bars back (a bar like the one before is no section)
SILENT_DB = -60.0      # a bar this quiet (mean level) is a break: it ends a replay and starts none (two
                       # silent bars sound alike, but a pause is no repeat)


class LiveForm:
    """Follows a stream's beats and bars; ``add_beats`` after each segment's beats, ``push`` the audio."""

    def __init__(self, sr: int, mode: str = "same", vary: float = 0.5):
        check_repeat(mode, vary)
        self.sr, self.mode = int(sr), mode
        self.new_from = int(round(PHRASE_BARS * (1.0 - vary))) if mode == "vary" else PHRASE_BARS
        self._audio = Ring(int(BUFFER_S * self.sr))   # the last BUFFER_S of audio, by global sample
        self._times: list[float] = []
        self._chroma: list[np.ndarray] = []      # per beat interval (beat k to k + 1)
        self._timbre: list[np.ndarray] = []
        self._bar_first: list[int] = []         # the beat each bar starts at
        self._bpb = 4
        self._source: list[int] = []
        self._entry: list[bool] = []
        self._offset: int | None = None          # bars back the music repeats, while it does
        self._since = 0                          # bars into the current replay
        self.repeats: list[tuple[int, int]] = []  # (bar, the bar it repeats) where a replay began
        self.boundaries: dict[int, int] = {0: 0}  # bar a section starts at -> the bar it was confirmed on
        if mode != "off":   # librosa's first feature call takes a second: before the stream, not in its first segment
            beat_features(np.sin(np.arange(self.sr) * 0.1).astype(np.float32), self.sr, np.zeros(1))

    def push(self, samples: np.ndarray) -> None:
        """Audio as it arrives (at ``sr``, mono)."""
        if self.mode == "off":
            return
        samples = np.asarray(samples, np.float32)
        for i in range(0, len(samples), self._audio.keep):   # a long stall's silence, a piece at a time
            self._audio.append(samples[i:i + self._audio.keep])

    def add_beats(self, times, bar_positions, beats_per_bar: int) -> None:
        """The beats given to the engine since the last call, in order, with their positions in the bar."""
        self._bpb = int(beats_per_bar)
        times = [float(t) for t in times]
        if self.mode == "off":   # nothing to follow: the beats are only counted
            self._times += times
            self._source += [-1] * len(times)
            self._entry += [False] * len(times)
            return
        chroma, timbre = self._features(np.array(self._times[-1:] + times))   # the intervals they close
        i = 0
        for t, pos in zip(times, bar_positions):
            k = len(self._times)
            if k:
                self._chroma.append(chroma[i])
                self._timbre.append(timbre[i])
                i += 1
            self._times.append(t)
            if pos == 0:
                if self._bar_first:
                    self._bar_complete()
                self._bar_first.append(k)
            self._plan_beat(k)

    @property
    def plan(self) -> FormPlan:
        n = len(self._times)
        return FormPlan(self.mode, np.array(self._source, dtype=np.int64), np.zeros(n, bool), np.zeros(n, bool),
                        (), np.array(self._entry, dtype=bool))

    def summary(self) -> dict:
        """What was recognised: the bars sections began at (and the bar each was confirmed on), the repeats."""
        return {"repeat": self.mode, "bars": len(self._bar_first),
                "section_bars": sorted(self.boundaries), "confirmed_at_bar": [self.boundaries[b] for b in
                                                                              sorted(self.boundaries)],
                "repeats": [list(r) for r in self.repeats],
                "replay_beats": int(np.sum(np.array(self._source) >= 0)) if self._source else 0}

    def bar_starts_s(self) -> np.ndarray:
        return np.array([self._times[b] for b in self._bar_first])

    def beat_times_s(self) -> np.ndarray:
        return np.array(self._times)

    # -- internals --------------------------------------------------------------------------------

    def _features(self, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The chroma and timbre of each interval between ``edges`` (zeros where its audio is gone)."""
        n = max(len(edges) - 1, 0)
        audio = self._audio.view()[-self._audio.keep:]     # the ring holds up to twice that
        start = self._audio.end - len(audio)
        a = int(round(edges[0] * self.sr)) - start if n else 0
        b = int(round(edges[-1] * self.sr)) - start if n else 0
        if not n or a < 0 or b > len(audio) or b - a < 512:
            return np.zeros((n, 12)), np.zeros((n, 14))
        return beat_features(audio[a:b], self.sr, edges[:-1] - edges[0])

    def _similarity(self, ordered: bool = True) -> np.ndarray:
        """``bar_similarity`` of the complete bars heard (the last ``MAX_BARS``)."""
        first = np.array(self._bar_first[-MAX_BARS:])
        last = first[-1] + self._bpb
        base = first[0]
        chroma = np.array(self._chroma[base:last])
        timbre = np.array(self._timbre[base:last])
        return bar_similarity(chroma, timbre, first - base, self._bpb, ordered=ordered)

    def _bar_complete(self) -> None:
        """The last bar is complete (a new downbeat came): follow or find a repeat, confirm boundaries."""
        n_bars = len(self._bar_first)            # complete bars (the new downbeat is not in the list yet)
        if n_bars < 2:
            return
        offset = n_bars - min(n_bars, MAX_BARS)  # bar index of the similarity's first row
        sim = self._similarity()
        c = n_bars - 1 - offset
        first = self._bar_first[-1]
        silent = np.mean([t[-1] for t in self._timbre[first:first + self._bpb]] or [0.0]) * 10.0 < SILENT_DB
        if self._offset is not None:             # (the timbre's last row is the level, dB / 10)
            if silent or c - self._offset < 0 or sim[c, c - self._offset] < STAY:
                self._offset = None
            else:
                self._since += 1
        if self._offset is None and c >= 1 and not silent:
            lags = np.arange(MIN_LAG_BARS, c + 1)
            lags = lags[c - lags - 1 >= 0]
            if lags.size:
                score = (sim[c, c - lags] + sim[c - 1, c - 1 - lags]) / 2.0
                best = int(np.argmax(score))
                if score[best] >= SAME_SECTION:
                    self._offset, self._since = int(lags[best]), 2
                    self.repeats.append((n_bars - 2, n_bars - 2 - self._offset))
        if n_bars >= 2 * KERNEL_BARS + MIN_SECTION_BARS:
            nov = novelty(self._similarity(ordered=False))
            for b in boundaries(nov[:c - KERNEL_BARS + 2]):
                if b + offset not in self.boundaries and all(abs(b + offset - x) >= MIN_SECTION_BARS
                                                             for x in self.boundaries):
                    self.boundaries[b + offset] = n_bars - 1

    def _plan_beat(self, k: int) -> None:
        """Beat k (the newest): the beat it replays, while the music repeats."""
        src, entry = -1, False
        if self._offset is not None and self.mode != "off" and self._bar_first:
            bar = len(self._bar_first) - 1
            into = k - self._bar_first[bar]
            pair = bar - self._offset
            if pair >= 0 and self._since % PHRASE_BARS < self.new_from:
                start = self._bar_first[pair]
                end = self._bar_first[pair + 1] if pair + 1 < len(self._bar_first) else start + self._bpb
                if start + into < end:
                    src = start + into
                    entry = into == 0 or not (self._source and self._source[-1] >= 0)
        self._source.append(src)
        self._entry.append(entry)
