"""A VMC receiver (the protocol's *Marionette*) written from its specification, to check what we send.

It listens on a UDP port (python-osc's server), collects each frame's ``/VMC/Ext/Bone/Pos``
messages until the frame's ``/VMC/Ext/T``, and rebuilds the avatar's pose as a receiver does: each
bone's world transform is its parent's composed with the local position and rotation it was sent
(in Unity's frame, as sent). ``dancesynth`` uses it in its tests and benchmark, and ``dancesynth
vmc-listen`` to show a user what reaches a port.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..rotations import apply, mul


@dataclass
class VmcFrame:
    t: float                                   # the sender's /VMC/Ext/T
    arrived: float                             # time.perf_counter() when the frame's last message came
    bones: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)   # name -> (pos, rot)
    root: tuple | None = None
    ok: int | None = None


class VmcReceiver:
    """Listens on ``127.0.0.1:port`` (0: any free port, then ``.port``); ``frames`` grows as bundles come."""

    def __init__(self, port: int = 0, host: str = "127.0.0.1"):
        from pythonosc.dispatcher import Dispatcher
        from pythonosc.osc_server import BlockingOSCUDPServer

        self.frames: list[VmcFrame] = []
        self._current = VmcFrame(0.0, 0.0)
        self._lock = threading.Lock()
        d = Dispatcher()
        d.map("/VMC/Ext/Bone/Pos", self._bone)
        d.map("/VMC/Ext/Root/Pos", self._root)
        d.map("/VMC/Ext/OK", self._ok)
        d.map("/VMC/Ext/T", self._time)
        self._server = BlockingOSCUDPServer((host, port), d)   # one thread: a bundle's messages stay in order
        self.port = self._server.server_address[1]
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="vmc-receiver", daemon=True)
        self._thread.start()

    def _bone(self, _address, name, *values):
        self._current.bones[str(name)] = (np.array(values[:3], dtype=np.float64), np.array(values[3:7], dtype=np.float64))

    def _root(self, _address, name, *values):
        self._current.root = (str(name), *values)

    def _ok(self, _address, loaded, *rest):
        self._current.ok = int(loaded)

    def _time(self, _address, t):
        self._current.t, self._current.arrived = float(t), time.perf_counter()
        with self._lock:
            self.frames.append(self._current)
        self._current = VmcFrame(0.0, 0.0)

    def wait_for(self, n: int, timeout_s: float) -> bool:
        """Wait until ``n`` frames came (or ``timeout_s`` passed); True when they did."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            with self._lock:
                if len(self.frames) >= n:
                    return True
            time.sleep(0.02)
        return False

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=2.0)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def vrm_pose(frame: VmcFrame) -> dict:
    """``frame`` as a VRM normalized pose, ``{vrm bone: {"rotation": xyzw, "position": xyz (the hips)}}``, in
    glTF's frame (three.js, three-vrm): what a bridge from VMC to a web page hands ``setNormalizedPose``
    (the hips' position is where the hips are; three-vrm takes it relative to the avatar's rest)."""
    from .vmc import to_unity, vrm_bone_name

    out = {}
    for name, (p, q) in frame.bones.items():
        bone = vrm_bone_name(name)
        if bone is None:
            continue
        pos, rot = to_unity(p, q)   # the mirror back
        out[bone] = {"rotation": rot.tolist(), **({"position": pos.tolist()} if bone == "hips" else {})}
    return out


def expected_positions(clip, bones: dict[str, int]) -> tuple[np.ndarray, tuple[int, ...]]:
    """What a receiver should rebuild from ``VmcFrames.of(clip, bones)``: (F, B, 3) every humanoid bone's position
    by our forward kinematics, in the order sent, in Unity's frame, and each bone's parent (as ``world_positions``
    takes it)."""
    from ..export.vrm import humanoid_tracks
    from ..kinematics import clip_fk
    from .vmc import to_unity

    tracks = humanoid_tracks(clip, bones)
    _, g_pos = clip_fk(clip)
    at = g_pos[:, list(tracks.joints)]
    at = at - at[:, :1] + tracks.hips_pos[:, None]     # the floor as the hips' track has it
    return to_unity(at, np.zeros(at.shape[:2] + (4,)) + [0.0, 0.0, 0.0, 1.0])[0], tracks.parent


def world_positions(frame: VmcFrame, names: tuple[str, ...], parent: tuple[int, ...]) -> np.ndarray:
    """(B, 3) each bone's position in the avatar's space (Unity's frame), from the local transforms
    ``frame`` holds, with the avatar's hierarchy: ``parent[k]`` the index in ``names`` of bone k's
    parent (-1: the hips, whose position is the avatar's)."""
    pos = np.zeros((len(names), 3))
    rot = np.zeros((len(names), 4))
    for k, name in enumerate(names):
        p, q = frame.bones[name]
        if parent[k] < 0:
            pos[k], rot[k] = p, q
        else:
            # Unity composes a child's transform with its parent's the same way in either handedness.
            pos[k] = pos[parent[k]] + apply(rot[parent[k]], p)
            rot[k] = mul(rot[parent[k]], q)
    return pos
