"""Re-dance a span of a dance, keeping the rest: the studio's edit.

``redance_span(clip, music, start_s, end_s, ...)`` snaps the span to the music's beats, dances the
span (with a bar of the music on each side, so the new moves are under way where they join) with
another seed, another style or a chosen motif, and splices it in:

- the new part is turned and moved so that at the span's first beat its root stands where the
  dance's does, facing the same way; the difference left at the last beat is spread over the span, the
  place's where the root travels and the facing's over its last ``TURN_S`` (so the dance after the
  span goes on from where it was, unchanged, and planted feet are not slid all along the span);
- planted feet are held through all this as the engines hold them through their blends (``engines.footlock``);
- over ``blend_s`` after the first beat and before the last, the poses cross-fade (smoothstep weights,
  quaternions along the shorter arc), as a motion graph's transition does;
- every frame outside the span is the dance's own, bit for bit.

The music is analysed once (``MusicFeatures`` of the whole song); only the span is danced again, so an
edit of a few bars of a long song costs a few bars' synthesis. Both clips must be on one skeleton
(retarget the part first: ``part_on`` does, with the dance's floor).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import rotations as rot
from .errors import InputError
from .types import MotionClip, MusicFeatures

BLEND_S = 0.4        # the cross-fade at each end of the span (a motion graph's blends take 0.3 s)
TURN_S = 2.0         # the facing's difference at the span's end is turned in over this long before it
CONTEXT_BARS = 1     # the music danced on each side of the span, so the new moves are under way at its ends


def span_beats(music: MusicFeatures, start_s: float, end_s: float) -> tuple[int, int]:
    """The beats nearest ``start_s`` and ``end_s``: the span as the music's beat indices (a, b), a < b."""
    beats = music.beat_times_s
    if not (np.isfinite(start_s) and np.isfinite(end_s)) or end_s <= start_s:
        raise InputError(f"a span needs a start before its end, got {start_s!r} to {end_s!r} s")
    if len(beats) < 3:
        raise InputError("the song has too few beats to re-dance a part of it")
    a, b = (int(np.argmin(np.abs(beats - t))) for t in (start_s, end_s))
    if b - a < 2:
        raise InputError(f"the span {start_s:.2f}-{end_s:.2f} s holds fewer than two beats: select at least "
                         "two beats (a bar or more re-dances best)")
    return a, b


def music_part(music: MusicFeatures, first: int, last: int, shift_s: float) -> MusicFeatures:
    """Beats ``first .. last`` of ``music`` as a song of their own starting ``shift_s`` earlier (form off:
    a few bars have none)."""
    times = music.beat_times_s[first:last + 1] - shift_s
    end_s = (music.duration_s if last == music.n_beats - 1 else music.beat_times_s[last]) - shift_s
    return replace(music, duration_s=float(end_s), beat_times_s=times,
                   intensity_db=music.intensity_db[first:last], structure=None,
                   beat_in_bar=None if music.beat_in_bar is None else music.beat_in_bar[first:last + 1])


def splice(base: MotionClip, part: MotionClip, offset: int, fa: int, fb: int, *,
           blend_s: float = BLEND_S, foot_lock: bool = True) -> MotionClip:
    """``base`` with its frames ``fa .. fb`` from ``part`` (whose frame 0 stands for ``base``'s frame
    ``offset``), aligned and cross-faded as the module says, its planted feet held (``foot_lock``)."""
    if part.skeleton.names != base.skeleton.names or part.fps != base.fps:
        raise InputError("the re-danced part is not on the dance's skeleton and frame rate; retarget it first")
    if not (0 <= fa < fb < base.n_frames and offset <= fa and fb - offset < part.n_frames):
        raise InputError(f"the part (frames {offset}-{offset + part.n_frames - 1}) does not cover the span "
                         f"{fa}-{fb} of a dance of {base.n_frames} frames")
    f = np.arange(fa, fb + 1)
    g = f - offset
    p_rot = part.local_rot[g].copy()
    p_pos = part.root_pos[g].copy()
    # Stand where the dance stands at the first beat, facing its way ...
    turn = rot.heading(base.local_rot[fa, 0]) - rot.heading(p_rot[0, 0])
    spin = rot.about_y(turn)
    flat = np.array([1.0, 0.0, 1.0])
    p_pos = rot.apply(spin, (p_pos - p_pos[0]) * flat) + base.root_pos[fa] * flat + p_pos * (1 - flat)
    p_rot[:, 0] = rot.mul(spin, p_rot[:, 0])
    # ... and end where it goes on from, the difference spread over the span where the root travels (a
    # dancer standing still is not slid: her planted feet would skate).
    # The facing's difference is turned in over the span's last TURN_S (a turn spread over the whole span
    # slides planted feet round all along it).
    drift_turn = _wrap(rot.heading(base.local_rot[fb, 0]) - rot.heading(p_rot[-1, 0]))
    turn_from = max(fb - TURN_S * base.fps, fa)
    p_rot[:, 0] = rot.mul(rot.about_y(_smoothstep((f - turn_from) / max(fb - turn_from, 1)) * drift_turn), p_rot[:, 0])
    steps = np.linalg.norm(np.diff(p_pos * flat, axis=0), axis=1)
    p_pos += _along(steps, f, fa, fb)[:, None] * ((base.root_pos[fb] - p_pos[-1]) * flat)
    # Cross-fade the poses in and out.
    width = max(min(blend_s * base.fps, (fb - fa) / 3), 1.0)
    weight = np.minimum(_smoothstep((f - fa) / width), _smoothstep((fb - f) / width))
    local_rot = base.local_rot.copy()
    root_pos = base.root_pos.copy()
    local_rot[f] = rot.nlerp(base.local_rot[f], p_rot, np.broadcast_to(weight[:, None], p_rot.shape[:2]))
    root_pos[f] = base.root_pos[f] * (1 - weight[:, None]) + p_pos * weight[:, None]
    local_pos = None
    if base.local_pos is not None and part.local_pos is not None:
        local_pos = base.local_pos.copy()
        local_pos[f] = base.local_pos[f] * (1 - weight[:, None, None]) + part.local_pos[g] * weight[:, None, None]
    contacts = None
    if base.contacts is not None and part.contacts is not None:
        contacts = base.contacts.copy()
        contacts[f] = np.where(weight[:, None] > 0.5, part.contacts[g], base.contacts[f])
    edited = replace(base, root_pos=root_pos, local_rot=local_rot, local_pos=local_pos, contacts=contacts,
                     meta=dict(base.meta))
    if foot_lock:
        edited.local_rot[f] = _feet_held(edited, f)
    return edited


def _feet_held(clip: MotionClip, f: np.ndarray) -> np.ndarray:
    """The span's frames ``f`` of ``clip`` with its planted feet held (``engines.footlock``, as the engines
    hold them through their blends): the cross-fades and the spread difference would slide them. The
    contacts are the spliced motion's own; the last ``HOLD_END_S`` hold none, so every correction has
    faded out when the span ends and the dance goes on as it was."""
    from .engines.footlock import FootLockState, LockParams, lock_feet
    from .engines.stitch import Rendered
    from .errors import ModelError
    from .motion.features import foot_contacts, foot_points
    from .motion.roles import find_roles

    try:
        roles = find_roles(clip.skeleton)
    except ModelError:   # no legs to hold
        return clip.local_rot[f]
    window = clip.frames(int(f[0]), int(f[-1]) + 1)
    params = LockParams()
    planted = foot_contacts(foot_points(window, roles), clip.fps)
    planted[max(len(f) - int(np.ceil((params.release_s + params.ease_s) * clip.fps)) - 1, 0):] = False
    frames = Rendered(window.local_rot, window.root_pos, planted, window.root_pos, window.local_rot, window.root_pos,
                      np.zeros(len(f), bool))
    held, _ = lock_feet(clip.skeleton, roles, frames, FootLockState(), fps=clip.fps, params=params)
    return held


def _along(amounts: np.ndarray, f: np.ndarray, fa: int, fb: int) -> np.ndarray:
    """0 at ``fa`` to 1 at ``fb``, rising with the running sum of ``amounts`` (one per frame step), or
    smoothly with time where they add up to nothing."""
    total = np.r_[0.0, np.cumsum(amounts)]
    return total / total[-1] if total[-1] > 1e-6 else _smoothstep((f - fa) / (fb - fa))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def redance_span(clip: MotionClip, music: MusicFeatures, start_s: float, end_s: float, *, database,
                 provenance=None, seed: int | None = None, style: str | None = None, motif: str | None = None,
                 onto=None, blend_s: float = BLEND_S) -> tuple[MotionClip, dict]:
    """``clip`` (a dance of ``music``, made by ``dance``; ``provenance``: its record when ``clip`` is a
    retargeted copy without one) with the span ``start_s .. end_s`` danced again by the same engine and
    configuration but ``seed`` (None: a fresh one), ``style`` (None: the dance's) or, with ``motif``
    (``"M17"``), by the choreography engine with that motif at the span's first beat.
    ``onto(part)``: what puts the new part on ``clip``'s skeleton (a retarget), if needed.

    Returns the edited dance and the edit's record (span in beats and seconds, what was asked)."""
    from .api import config_from_report, dance
    from .types import check_seed

    prov = provenance if provenance is not None else clip.provenance
    if prov is None:
        raise InputError("only a dance made by dancesynth (with its provenance) can be re-danced in part")
    a, b = span_beats(music, start_s, end_s)
    if seed is None:
        seed = int(np.random.default_rng().integers(0, 2**31 - 1))
    check_seed(seed)
    config = replace(config_from_report(prov.report()), seed=seed, style=style or prov.style, repeat="off",
                     recreate=None)
    if motif:
        config = replace(config, engine="choreography", follow_signature=False, lookahead_s=0.0, model=None)
    beats = music.beat_times_s
    # The span with a bar of context each side, as a song of its own from a whole frame of the dance.
    per_bar = music.beats_per_bar or 4
    first, last = max(a - CONTEXT_BARS * per_bar, 0), min(b + CONTEXT_BARS * per_bar, music.n_beats - 1)
    offset = int(np.floor(beats[first] * clip.fps))
    shift_s = offset / clip.fps
    at = () if not motif else ((float((beats[a] + beats[a + 1]) / 2 - shift_s), motif),)
    part = dance(music_part(music, first, last, shift_s), config=replace(config, motif_at=at), database=database)
    if onto is not None:
        part = onto(part)
    fa, fb = (int(round(beats[i] * clip.fps)) for i in (a, b))
    edited = splice(clip, part, offset, fa, fb, blend_s=blend_s)
    record = {"start_s": float(beats[a]), "end_s": float(beats[b]), "beats": [a, b], "seed": seed,
              "style": part.provenance.style if part.provenance is not None else config.style,
              "engine": config.engine, "motif": motif or None}
    edits = list(prov.summary.get("edits", [])) + [record]
    edited.provenance = prov.with_summary(edits=edits)
    return edited, record
