"""The live dance sent to avatar apps over the VMC protocol (OSC over UDP).

VSeeFace, VNyan, Warudo, 3tene, VirtualMotionCapture and the EVMC4U (Unity), VMC4UE (Unreal),
VMC4B (Blender) and Godot receivers take an avatar's pose as the protocol's *Marionette*
side reads it (protocol.vmc.info, marionette spec, v2.0 messages; usually port 39539). Each
frame is one OSC bundle:

- ``/VMC/Ext/Root/Pos "root" 0 0 0 0 0 0 1``: the avatar's root stays where the app put it;
- ``/VMC/Ext/Bone/Pos name p.x p.y p.z q.x q.y q.z q.w`` for every humanoid bone the character
  has: its local position and rotation relative to its nearest humanoid parent, the rotation
  relative to the VRM T-pose (a normalized VRM's bones rest at identity, as UniVRM and
  three-vrm's normalized bones do), the hips' position carrying the dance's travel and height;
- ``/VMC/Ext/OK 1`` (a model is loaded) and ``/VMC/Ext/T`` (seconds since the dance began).

Names are Unity's ``HumanBodyBones`` (``Hips``, ``LeftUpperArm``; VRM 1.0's thumb metacarpal,
proximal and distal are Unity's thumb proximal, intermediate and distal). Unity is left-handed:
positions and rotations are glTF's (Y up, the avatar facing +Z) mirrored in x, ``p = (-x, y, z)``,
``q = (x, -y, -z, w)``, as UniVRM imports a VRM 1.0.

``VmcSender`` sends on a steady clock of its own: frame ``i`` goes out ``i / fps`` after the
first, whatever the synthesis thread is doing. Segments arrive as they are danced; when the
next frame is not there on time (a late segment), the last pose is held, and when frames come
again the sender goes on from the frame due at that moment (the dance stays on the music),
blended from the held pose over ``BLEND_S``: the avatar never jumps. A receiver that is not
listening or a full socket buffer loses that frame's bundle, counted, never the dance.
"""

from __future__ import annotations

import socket
import threading
import time
from collections import deque
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from ..errors import InputError
from ..rotations import nlerp

DEFAULT_PORT = 39539
BLEND_S = 0.25           # from a held pose back into the dance (a late segment)
MARGIN_S = 0.2          # the clock starts this long after the first frames: the next segment's synthesis
                        # may take longer than the first's without the avatar holding a pose
SLEW = 0.03             # the clock moves toward the music's bar lines by at most this share of each frame
LOG_S = 600.0            # the send log kept (a long stream's counts stay in ``stats``)
QUEUE_S = 600.0          # frames kept waiting at most (a file read faster than real time: the oldest go)


def unity_bone_name(vrm_bone: str) -> str:
    """VRM 1.0 humanoid bone name -> Unity ``HumanBodyBones`` name (what VMC receivers look up)."""
    for side in ("left", "right"):
        if vrm_bone.startswith(side + "Thumb"):
            part = vrm_bone[len(side) + len("Thumb"):]
            unity_part = {"Metacarpal": "Proximal", "Proximal": "Intermediate", "Distal": "Distal"}[part]
            return side.capitalize() + "Thumb" + unity_part
    return vrm_bone[0].upper() + vrm_bone[1:]


@lru_cache(maxsize=1)
def _vrm_bones() -> dict[str, str]:
    from ..retarget.humanoid import BONES

    return {unity_bone_name(b): b for b in BONES}


def vrm_bone_name(unity_bone: str) -> str | None:
    """Unity ``HumanBodyBones`` name -> VRM 1.0 humanoid bone name (None: not a VRM bone)."""
    return _vrm_bones().get(unity_bone)


def to_unity(pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """glTF (right-handed, Y up, facing +Z) positions (..., 3) and (x, y, z, w) rotations (..., 4) in Unity's
    left-handed frame: mirrored in x (its own inverse: Unity's back to glTF's too)."""
    p = np.array(pos, dtype=np.float64)
    q = np.array(rot, dtype=np.float64)
    p[..., 0] *= -1.0
    q[..., 1:3] *= -1.0
    return p, q


@dataclass(frozen=True)
class VmcFrames:
    """Frames ready to send: ``names`` (B,) Unity bone names, ``pos`` (F, B, 3) and ``rot`` (F, B, 4) each
    bone's local position and rotation in Unity's frame."""

    names: tuple[str, ...]
    pos: np.ndarray
    rot: np.ndarray

    @property
    def n_frames(self) -> int:
        return len(self.pos)

    @classmethod
    def of(cls, clip, bones: dict[str, int]) -> "VmcFrames":
        """A dance ``clip`` on a character whose humanoid ``bones`` (VRM name -> joint) rest in the VRM T-pose."""
        from ..export.vrm import humanoid_tracks

        tracks = humanoid_tracks(clip, bones)
        pos = np.repeat(tracks.rest_local[None], tracks.rotations.shape[0], axis=0)
        pos[:, 0] = tracks.hips_pos
        pos, rot = to_unity(pos, tracks.rotations)
        return cls(tuple(unity_bone_name(b) for b in tracks.bones), pos, rot)


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (or ``HOST``, or ``:PORT``) -> (host, port); a clear error otherwise."""
    host, _, port = str(text).rpartition(":") if ":" in str(text) else (str(text), "", str(DEFAULT_PORT))
    host = host or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 1 <= number <= 65535:
        raise InputError(f"--vmc {text}: give HOST:PORT with a port from 1 to 65535 (VMC apps listen on "
                         f"{DEFAULT_PORT})")
    try:
        socket.getaddrinfo(host, number, type=socket.SOCK_DGRAM)
    except socket.gaierror as exc:
        raise InputError(f"--vmc {text}: cannot resolve host {host!r} ({exc.strerror})") from None
    return host, number


def bundle(names: tuple[str, ...], pos: np.ndarray, rot: np.ndarray, t: float) -> bytes:
    """One frame's OSC bundle (the module's text lists what it holds)."""
    out = OscBundleBuilder(IMMEDIATELY)

    def message(address, *args):
        m = OscMessageBuilder(address=address)
        for a in args:
            m.add_arg(a)
        out.add_content(m.build())

    message("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for name, p, q in zip(names, pos.tolist(), rot.tolist()):
        message("/VMC/Ext/Bone/Pos", name, *p, *q)
    message("/VMC/Ext/OK", 1)
    message("/VMC/Ext/T", float(t))
    return out.build().dgram


class VmcSender:
    """Sends frames pushed to it (``push``: a ``VmcFrames``) to ``host:port`` at ``fps`` on its own thread.

    ``log`` keeps, per bundle sent (the last ``LOG_S``), the frame shown or -1 for a held pose, when it was
    due and when it went out (``time.perf_counter`` seconds); ``stats`` counts the whole stream. ``close``
    waits until every pushed frame went out, then stops."""

    def __init__(self, host: str, port: int, fps: float, *, blend_s: float = BLEND_S, margin_s: float = MARGIN_S):
        self.address = (host, port)
        self.fps = float(fps)
        self.margin_s = float(margin_s)
        self.blend = max(1, int(round(blend_s * fps)))
        family = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0][0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)     # a full buffer loses a bundle, it never stalls the clock
        self._lock = threading.Lock()
        self._names: tuple[str, ...] | None = None
        self._pos: list[np.ndarray] = []
        self._rot: list[np.ndarray] = []
        self.pushed = 0                   # frames pushed so far (the index of the next one)
        self._base = 0                    # index of self._pos[0]
        self._closing = False
        self._abort = False
        self._start: float | None = None  # when frame 0 is due (time.perf_counter)
        self._target: float | None = None  # where ``align`` wants the start, slewed to a frame at a time
        self._earliest: float | None = None  # the delay the clock first started with (the least it may have)
        self.delay_s: float | None = None  # after ``align``: how far behind the music the avatar dances
        self.log: deque[tuple[int, float, float]] = deque(maxlen=int(LOG_S * fps))
        self.bundles = self.on_time = 0   # bundles sent; those sent within a frame period of their time
        self.dropped = 0                  # bundles the socket refused
        self.held = 0                     # bundles that repeated a held pose
        self.skipped = 0                  # frames skipped because this thread itself was held up
        self._thread = threading.Thread(target=self._run, name="dancesynth-vmc", daemon=True)
        self._started = False

    def push(self, frames: VmcFrames) -> None:
        with self._lock:
            if self._names is None:
                self._names = frames.names
            elif frames.names != self._names:
                raise InputError("VMC: a segment's bones differ from the first segment's")
            self._pos.extend(frames.pos)
            self._rot.extend(frames.rot)
            self.pushed += frames.n_frames
            keep = int(QUEUE_S * self.fps)
            if len(self._pos) > keep:
                cut = len(self._pos) - keep
                del self._pos[:cut], self._rot[:cut]
                self._base += cut
        if not self._started:
            self._started = True
            with self._lock:
                if self._start is None:
                    self._start = time.perf_counter() + self.margin_s
            self._thread.start()

    def align(self, audio_start: float, bar_s: float) -> None:
        """Keep the avatar a whole number of bars behind the music: the dance's 0 s is the music's 0 s, heard at
        ``audio_start`` (``time.perf_counter``), and a bar lasts ``bar_s`` at the tempo heard so far. A move made
        for a beat (a downbeat) is then shown as a beat (a downbeat) is heard. Before the first frame the
        clock's start moves to the next bar line after it; later, as the tempo heard is known better, the
        clock slews toward the nearest bar line (at most ``SLEW`` of a frame period a frame: a few per cent
        faster or slower, never a jump), never earlier than it first started."""
        with self._lock:
            start = self._start if self._start is not None else time.perf_counter() + self.margin_s
            if not bar_s > 0:
                return
            if self._earliest is None:
                self._earliest = start - audio_start
            bars = max(np.ceil(self._earliest / bar_s - 1e-9), np.round((start - audio_start) / bar_s))
            target = audio_start + float(bars) * bar_s
            if not self.bundles and start > time.perf_counter():
                self._start = target
            else:
                self._target = target
            self.delay_s = target - audio_start

    def close(self, drain: bool = True) -> None:
        """Stop once every pushed frame went out (``drain``), or at once (an interrupted stream)."""
        with self._lock:
            self._closing = True
            self._abort = not drain
        if self._started:
            self._thread.join()
        self._sock.close()

    def stats(self) -> dict:
        """Bundles sent, the share that went out within one frame period of their time, poses held
        while a segment was late, bundles the socket refused, frames skipped when the sender was held up."""
        return {"bundles": self.bundles, "on_time": self.on_time / self.bundles if self.bundles else 1.0,
                "held": self.held, "lost": self.dropped, "skipped": self.skipped}

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(drain=exc_type is None)

    def _run(self) -> None:
        index = tick = 0            # the next frame of the dance to show; the clock's frame count
        last = held = blend = None  # the pose shown last; the pose held while late; (pose, frame) blended from
        while True:
            while True:   # (align may move the start later until the first frame is due: look again)
                with self._lock:
                    due = self._start + tick / self.fps
                wait = due - time.perf_counter()
                if wait <= 0 or self.bundles:
                    break
                time.sleep(min(wait, 0.05))
            if wait > 0:
                time.sleep(wait)
            elif -wait >= 1.0 / self.fps:  # this thread was held up: skip to the frame due now, not a burst
                behind = int(-wait * self.fps)
                tick, due = tick + behind, due + behind / self.fps
                index += 0 if held is not None else behind
                self.skipped += behind
            with self._lock:
                available, closing = self.pushed, self._closing
                if self._abort or (closing and index >= available):
                    return
                if index < available:
                    if held is not None:   # frames again after a wait: on from the frame due now (the music's)
                        index = min(tick, available - 1)
                        blend, held = (held, index), None
                    index = max(index, self._base)   # (far behind: the oldest frame kept)
                    pos, rot = self._pos[index - self._base], self._rot[index - self._base]
            if index < available:
                if blend is not None:
                    w = (index - blend[1] + 1) / (self.blend + 1)
                    if w < 1.0:
                        pos, rot = blend[0][0] + w * (pos - blend[0][0]), nlerp(blend[0][1], rot, w)
                    else:
                        blend = None
                shown, last = index, (pos, rot)
                index += 1
            else:                          # late: the last pose, held
                held = held or last
                (pos, rot), shown = held, -1
                self.held += 1
            with self._lock:
                if self._target is not None:   # toward the bar line, a little each frame
                    step = np.clip(self._target - self._start, -SLEW / self.fps, SLEW / self.fps)
                    self._start += float(step)
                    self._target = None if self._start == self._target else self._target
            self._send(pos, rot, tick / self.fps)
            sent = time.perf_counter()
            self.log.append((shown, due, sent))
            self.bundles += 1
            self.on_time += sent - due < 1.0 / self.fps
            tick += 1

    def _send(self, pos, rot, t: float) -> None:
        try:
            self._sock.sendto(bundle(self._names, np.asarray(pos), np.asarray(rot), t), self.address)
        except OSError:                  # nobody listening (ICMP refused), a full buffer: this frame is lost
            self.dropped += 1
