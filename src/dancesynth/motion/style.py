"""The types of the motion database (``motion.database`` builds, stores and opens them): a ``Style``,
clips of one genre, tempo range and skeleton as flat arrays plus clip ranges (Holden's motion-matching
layout), with its motion beats, per-frame kinetic energy and foot contacts; and a ``MotionDatabase``,
its styles by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..errors import InputError
from ..types import MotionClip, Skeleton
from .mirror import mirror_motion


@dataclass(eq=False)
class Style:
    """One sub-group of the database: clips of one genre, tempo range and skeleton."""

    name: str
    genre: str
    skeleton: Skeleton
    fps: float
    clip_names: tuple[str, ...]
    clip_sources: tuple[str, ...]
    clip_starts: np.ndarray      # (C+1,) frame offsets of each clip in the flat arrays
    local_rot: np.ndarray        # (F, J, 4) float32
    root_pos: np.ndarray         # (F, 3) float32, metres
    contacts: np.ndarray         # (F, 2) bool, (left, right) foot planted
    energy: np.ndarray           # (F,) float32 kinetic energy, joules
    beat_frames: np.ndarray      # (B,) int64 flat frame index of every motion beat
    clip_tempo_bpm: np.ndarray   # (C,)
    fingerprint: str = ""
    clip_licences: tuple[str, ...] = ()   # per clip, from the manifest's [licences] ("" where none is recorded)
    mirror: bool = False         # dance it with each take's mirror image too (``material``; manifest [mirror])
    n_mirrored: int = 0          # the last n_mirrored clips are mirrored takes of the first ones (``material``)

    @property
    def licences(self) -> tuple[str, ...]:
        """The licences of the style's clips, each once ("unrecorded" for clips without one)."""
        return tuple(dict.fromkeys(x or "unrecorded" for x in (self.clip_licences or ("",) * self.n_clips)))

    @property
    def n_clips(self) -> int:
        return len(self.clip_names)

    @property
    def n_frames(self) -> int:
        return len(self.local_rot)

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    @property
    def captured_s(self) -> float:
        """Seconds of captured motion (mirrored takes not counted)."""
        return float(self.clip_starts[self.n_clips - self.n_mirrored]) / self.fps

    @property
    def mirrored_s(self) -> float:
        """Seconds of mirrored takes the style is danced with (``material``)."""
        return self.captured_s if self.mirror else 0.0

    @cached_property
    def material(self) -> "Style":
        """What the engines dance: the captured clips and, for a style marked ``mirror``, each one's
        left-right mirror image after them (``motion.mirror``: contacts swapped, the same motion
        beats, energies and tempi), named '<clip> (mirrored)'. Analyses and held-out evaluations
        read the style itself, whose clips are all captured."""
        if not self.mirror or self.n_mirrored:
            return self
        rot, pos, contacts = mirror_motion(self.skeleton, self.local_rot, self.root_pos, self.contacts)
        n = self.n_frames
        return Style(self.name, self.genre, self.skeleton, self.fps,
                     self.clip_names + tuple(f"{c} (mirrored)" for c in self.clip_names),
                     self.clip_sources * 2, np.r_[self.clip_starts, self.clip_starts[1:] + n],
                     np.concatenate([self.local_rot, rot.astype(np.float32)]),
                     np.concatenate([self.root_pos, pos.astype(np.float32)]),
                     np.concatenate([self.contacts, contacts]), np.r_[self.energy, self.energy],
                     np.r_[self.beat_frames, self.beat_frames + n], np.r_[self.clip_tempo_bpm, self.clip_tempo_bpm],
                     f"{self.fingerprint}+mirrored", self.clip_licences * 2 if self.clip_licences else (),
                     mirror=True, n_mirrored=self.n_clips)

    @property
    def tempo_range_bpm(self) -> tuple[float, float]:
        return float(self.clip_tempo_bpm.min()), float(self.clip_tempo_bpm.max())

    @property
    def natural_tempo_bpm(self) -> float:
        return float(np.median(self.clip_tempo_bpm))

    def clip_of_frame(self, frames) -> np.ndarray:
        return np.searchsorted(self.clip_starts, frames, side="right") - 1

    def clip(self, index: int) -> MotionClip:
        """Clip ``index`` as a ``MotionClip`` (float64), with its beats in ``meta``."""
        a, b = int(self.clip_starts[index]), int(self.clip_starts[index + 1])
        beats = self.beat_frames[(self.beat_frames >= a) & (self.beat_frames < b)] - a
        return MotionClip(self.skeleton, self.fps, self.root_pos[a:b], self.local_rot[a:b],
                          contacts=self.contacts[a:b],
                          meta={"name": self.clip_names[index], "source": self.clip_sources[index],
                                "style": self.name, "beat_frames": beats})

    def without_clip(self, index: int) -> "Style":
        """The style with clip ``index`` left out (held-out evaluations: re-create a dance not in the style);
        its mirror image goes with it (the style keeps ``mirror``: its ``material`` mirrors the clips left)."""
        if self.n_mirrored:
            raise ValueError("leave clips out of the style, not of its material")
        a, b = int(self.clip_starts[index]), int(self.clip_starts[index + 1])
        keep = np.r_[0:a, b:self.n_frames]
        beats = self.beat_frames[(self.beat_frames < a) | (self.beat_frames >= b)]
        return Style(self.name, self.genre, self.skeleton, self.fps,
                     self.clip_names[:index] + self.clip_names[index + 1:],
                     self.clip_sources[:index] + self.clip_sources[index + 1:],
                     np.r_[self.clip_starts[:index + 1], self.clip_starts[index + 2:] - (b - a)],
                     self.local_rot[keep], self.root_pos[keep], self.contacts[keep], self.energy[keep],
                     np.where(beats >= b, beats - (b - a), beats), np.delete(self.clip_tempo_bpm, index),
                     f"{self.fingerprint}-without-{index}",
                     self.clip_licences[:index] + self.clip_licences[index + 1:], mirror=self.mirror)


@dataclass(eq=False)
class MotionDatabase:
    styles: dict[str, Style]
    source: str = ""
    notes: dict = field(default_factory=dict)

    def genres(self) -> list[str]:
        return sorted({s.genre for s in self.styles.values()})

    def styles_of(self, name: str) -> list[Style]:
        """Styles called ``name``, or all styles of genre ``name``; a clear error otherwise."""
        if name in self.styles:
            return [self.styles[name]]
        found = [s for s in self.styles.values() if s.genre == name]
        if not found:
            raise InputError(f"unknown style '{name}': this database has {', '.join(sorted(self.styles))} "
                             f"(run 'dancesynth styles' to list them)")
        return found
