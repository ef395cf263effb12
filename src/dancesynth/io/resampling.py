"""Resampling decoded audio with soxr, whole or block by block as it is decoded.

soxr's stream resampler gives, sample for sample, what resampling the whole signal at once
gives, so a long song is resampled as it is read and never held twice.
"""

from __future__ import annotations

import numpy as np


def resample(y: np.ndarray, sr_in: int, sr_out: int) -> np.ndarray:
    """Resample ``(n,)`` or ``(channels, n)`` samples with soxr (high quality)."""
    import soxr

    if sr_in == sr_out:
        return y
    if y.ndim == 1:
        return soxr.resample(y, sr_in, sr_out, quality="HQ").astype(np.float32, copy=False)
    # soxr wants (frames, channels).
    return soxr.resample(y.T, sr_in, sr_out, quality="HQ").T.astype(np.float32, copy=False)


def resample_blocks(blocks, sr_in: int, sr_out: int):
    """Resample mono float32 blocks as one signal: yields the output in blocks.

    soxr's stream resampler: the concatenated output is the same, sample for
    sample, as ``resample`` of the concatenated input, without the whole signal
    (or its resampled copy) ever being in memory.
    """
    if sr_in == sr_out:
        for block in blocks:
            yield np.asarray(block, dtype=np.float32)
        return
    import soxr

    stream = soxr.ResampleStream(sr_in, sr_out, 1, dtype="float32", quality="HQ")
    for block in blocks:
        out = stream.resample_chunk(np.ascontiguousarray(block, dtype=np.float32), last=False)
        if len(out):
            yield out
    out = stream.resample_chunk(np.zeros(0, dtype=np.float32), last=True)
    if len(out):
        yield out


class Sink:
    """Decoded blocks in, one ``(channels, n)`` float32 array out: resampled as they come
    (soxr's stream resampler gives the same samples as ``resample`` of the whole signal), written
    into an array of the expected length (grown when a header understated it), and checked for
    samples that are not finite."""

    def __init__(self, sr_in: int, sr_out: int, channels: int, expected_frames: int):
        self.sr_in, self.sr_out, self.channels = sr_in, sr_out, channels
        self.frames_in = 0
        self.n = 0
        self.finite = True
        self._stream = None
        if sr_in != sr_out:
            import soxr

            self._stream = soxr.ResampleStream(sr_in, sr_out, channels, dtype="float32", quality="HQ")
        expected = int(np.ceil(expected_frames * sr_out / sr_in)) + 64 if expected_frames > 0 else 0
        self._buf = np.empty((channels, max(expected, 1 << 16)), dtype=np.float32)

    def add(self, block: np.ndarray) -> None:
        """``block``: ``(frames,)`` when mono, else ``(frames, channels)`` float32."""
        self.frames_in += len(block)
        if self._stream is not None:
            block = self._stream.resample_chunk(block, last=False)
        self._put(block)

    def finish(self) -> np.ndarray:
        if self._stream is not None:
            empty = np.zeros((0,) if self.channels == 1 else (0, self.channels), dtype=np.float32)
            self._put(self._stream.resample_chunk(empty, last=True))
            self._stream = None
        if self._buf.shape[1] - self.n > 1 + self._buf.shape[1] // 64:
            # A header that overstated the length left room unused: give it back (in place where
            # the layout allows, so a long song is never held twice).
            if self.channels == 1:
                self._buf.resize((1, self.n), refcheck=False)
            else:
                self._buf = self._buf[:, :self.n].copy()
        return self._buf[:, :self.n]

    def _put(self, block: np.ndarray) -> None:
        k = len(block)
        if k == 0:
            return
        if self.n + k > self._buf.shape[1]:
            grown = np.empty((self.channels, max(self.n + k, self._buf.shape[1] * 3 // 2)), dtype=np.float32)
            grown[:, :self.n] = self._buf[:, :self.n]
            self._buf = grown
        out = self._buf[:, self.n:self.n + k]
        out[...] = block.T if block.ndim == 2 else block
        if self.finite and not np.isfinite(out).all():
            self.finite = False
        self.n += k
