"""Dancing with the learned pose generator (``dance --engine neural``).

song -> beat grid and per-beat intensity -> one target motif per beat (the
choreography level) and a real word of that motif to show the network -> the
acLSTM runs frame by frame at ``data.TRAIN_FPS``, told the phase of the music's
beat, the motif words of this beat and the next and, through AdaIN, the beat's
intensity -> each channel widened toward the mocap's spread (``data.restore_spread``) ->
poses decoded, resampled to the output rate, planted feet held and hands kept out of
the head with IK.

Beats land on the music because the generator is conditioned on the music's beat
phase: it learned from the mocap that a motion beat (a pose where the body's
motion turns) falls at phase 0.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...errors import InputError, ModelError
from ...kinematics import fk
from ...motion.accents import cached_peak_speeds
from ...motion.beats import kinematic_beats, summed_speed
from ...motion.database import MotionDatabase
from ...motion.features import foot_contacts, foot_points
from ...motion.resample import sample_frames
from ...motion.roles import find_roles
from ...provenance import EngineRun
from ...types import MotionClip, MusicFeatures
from ..beatgrid import RATE_RANGE, StyleFit, beat_grid, equally_good, fit_summary, style_fits
from ..footlock import FootLockState, lock_feet
from ..form import form_plan, replay_motion
from ..handclear import keep_hands_out_of_head
from ..stitch import Rendered
from ..timing import SpeedRoom
from .data import TRAIN_FPS, beat_phase, conditioning, decode_pose, hamming_weights, music_vectors, restore_spread
from .store import StoredModel, find_model, load_model, model_id

DEFAULT_GENRE = "salsa"   # the genre of the shipped model


# Most the post-filter widens a channel. 1.2, then 1.15, were chosen on the bench's own songs and held-out
# take; chosen on a validation set instead (benchmarks/spread_cap_select.py: the tune split's generated
# songs, tuning seeds, against the takes the model was trained on), every cap above 1 raised FID_k (50 at 1,
# 68 at 1.15, 78 at 1.2) and left FID_g where it was: the filter is off by default (docs/neural.md).
SPREAD_CAP = 1.0


def motif_plan(n_beats: int, template, transitions, rng: np.random.Generator) -> np.ndarray:
    """One target motif per beat interval by the choreography level's eq. (5); -1s without motifs."""
    if template is None:
        return np.full(n_beats, -1)
    from ..choreography.level import plan_motifs

    return plan_motifs(n_beats, template, transitions, rng)


#: The beat warp may speed the generated motion up only while its fastest joint stays under this percentile
#: of the style's own fastest-joint speeds. Chosen on the tune split (25 generated songs): without it 1 song
#: lay outside +-25 % of the mocap's p99 joint speed, at 99 none, with accent precision 0.537 -> 0.519;
#: at 96 (the easing's limit) or 98 precision fell to 0.43 / 0.48, every dropped anchor a beat not hit.
#: None: no limit.
WARP_SPEED_PERCENTILE: float | None = 99.0


def beat_warp(motion_beats_s: np.ndarray, music_beats_s: np.ndarray, *, reach: float = 0.5,
              rates=(0.67, 1.5), speed=None, speed_limit: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Anchors ``(music_s, motion_s)`` of a light time-warp that puts generated beats on music beats.

    Each music beat takes the nearest generated motion beat within ``reach`` of its
    beat period; anchors that would run time backwards or change the playback rate
    outside ``rates`` are dropped. Between anchors time is interpolated linearly.
    ``speed`` ``(times_s, m_s)``: the motion's fastest joint's speed over its time; an anchor that would
    play a stretch faster than captured and push its fastest moment past ``speed_limit`` is dropped
    too (the next beat may still take it), as the easing takes only the speed headroom a piece has.
    """
    m = np.asarray(music_beats_s, dtype=float)
    g = np.asarray(motion_beats_s, dtype=float)
    if len(m) < 2 or len(g) == 0:
        return np.zeros(0), np.zeros(0)
    period = np.gradient(m)
    j = np.clip(np.searchsorted(g, m), 1, len(g)) - 1
    j = np.where((j + 1 < len(g)) & (np.abs(g[np.minimum(j + 1, len(g) - 1)] - m) < np.abs(g[j] - m)), j + 1, j)
    keep = np.abs(g[j] - m) <= reach * period
    am, ag = [], []
    for mi, gi in zip(m[keep], g[j[keep]]):
        rate = (gi - ag[-1]) / (mi - am[-1]) if am else 1.0
        if am and not (rates[0] <= rate <= rates[1]):
            continue
        if am and speed is not None and rate > 1.0 and rate * _peak(speed, ag[-1], gi) > speed_limit:
            continue
        am.append(mi)
        ag.append(gi)
    return np.array(am), np.array(ag)


def _peak(speed, a: float, b: float) -> float:
    """The fastest ``speed`` (``(times_s, m_s)``) between motion times ``a`` and ``b``."""
    t, v = speed   # t ascending: a slice, not a mask over the whole song for every beat
    inside = v[np.searchsorted(t, a, side="left"):np.searchsorted(t, b, side="right")]
    return float(inside.max()) if inside.size else 0.0


def _warp_positions(t_out: np.ndarray, anchors) -> np.ndarray:
    """Motion times for output times: the anchors' piecewise-linear map, shifted beyond its ends.

    Before the first anchor the map is shifted, unless that would ask for motion before
    the first generated frame: then it runs from (0, 0) to the anchor, so the dance never
    freezes on its first pose (the generated motion starts at 0 s).
    """
    am, ag = anchors
    if len(am) == 0:
        return t_out.copy()
    src = np.interp(t_out, am, ag)
    head = t_out + (ag[0] - am[0]) if ag[0] >= am[0] or ag[0] <= 0 else t_out * (ag[0] / am[0])
    src = np.where(t_out < am[0], head, src)
    return np.where(t_out > am[-1], t_out + (ag[-1] - am[-1]), src)


def generate(model: StoredModel, music: MusicFeatures, grid, motifs: np.ndarray, *, fps: float,
             seed: int = 0, spread_cap: float = SPREAD_CAP, speed_limit: float = np.inf) -> MotionClip:
    """Run the generator over ``grid`` (a ``BeatGrid``) and return the dance at ``fps``.

    ``spread_cap`` > 1 widens the generated motion toward the training data's spread by at most
    that factor (``data.restore_spread``); 1 leaves the network's motion as it is. ``speed_limit``
    (m/s): the fastest the beat warp may push a joint by speeding the motion up (``beat_warp``).
    """
    import torch

    from ...threads import torch_threads

    torch_threads()  # one thread by default: 3.5-5.6x faster than torch's thread per core here
    gen = model.generator
    n = int(np.floor(music.duration_s * TRAIN_FPS)) + int(2 * TRAIN_FPS)   # two seconds to spare for the warp
    k, phase, length_s = beat_phase(n, grid.times_s * TRAIN_FPS, TRAIN_FPS)
    rng = np.random.default_rng(seed)
    words = model.motif_words_for(motifs, rng)
    cond = torch.as_tensor(conditioning(phase, length_s, words, k))
    music_w = torch.as_tensor(music_vectors(grid.intensity_db, np.diff(grid.times_s))[k])
    window = torch.as_tensor(hamming_weights(phase))
    start = model.start_poses[rng.integers(len(model.start_poses))]
    prev = torch.as_tensor((start - model.mean) / model.std, dtype=torch.float32)[None]
    out = np.empty((n, len(model.mean)), dtype=np.float32)
    with torch.inference_mode():
        state = gen.initial_state(1)
        for t in range(n):
            y, state = gen.step(prev, cond[t:t + 1], music_w[t:t + 1], window[t:t + 1], state)
            prev = gen.feedback(y)
            out[t] = prev[0].numpy()
    if model.spread is None:   # a model trained before the post-filter: the network alone
        spread_cap = 1.0
    if spread_cap > 1.0:       # every channel but the foot contacts
        out = restore_spread(out, model.spread, out.shape[1] - 2, spread_cap)
    poses = out * model.std + model.mean
    local, root, contacts = decode_pose(poses, TRAIN_FPS)
    sk = model.skeleton
    # Two passes of the beat warp: warping moves speed minima a little, the second pass catches them.
    n_out = int(np.floor(music.duration_s * fps - 1e-9)) + 1
    t_out = np.arange(n_out) / fps
    src_s = t_out.copy()
    for _ in range(2):
        w_local, w_root, _ = sample_frames(local, root, np.clip(src_s, 0.0, (n - 1) / TRAIN_FPS) * TRAIN_FPS)
        _, pos = fk(w_local, w_root, sk.offsets, sk.parents)
        beats_s = kinematic_beats(summed_speed(pos, fps), fps)[0] / fps
        fastest = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1) * fps
        anchors = beat_warp(beats_s, grid.times_s,   # the grid beats the generator was told (phase 0)
                            speed=(t_out[:-1] + 0.5 / fps, fastest), speed_limit=speed_limit)
        x = _warp_positions(t_out, anchors)
        # The previous pass's map, at slope 1 beyond its ends (np.interp alone would freeze them).
        src_s = np.where(x > t_out[-1], src_s[-1] + (x - t_out[-1]),
                         np.where(x < 0, src_s[0] + x, np.interp(x, t_out, src_s)))
    src_s = np.clip(src_s, 0.0, (n - 1) / TRAIN_FPS)
    local, root, _ = sample_frames(local, root, src_s * TRAIN_FPS, contacts)
    # The feet the generated motion itself plants (low and slow), found as in the database's
    # analysis: more reliable than the network's own contact outputs after a short training.
    roles = find_roles(sk)
    contacts = foot_contacts(foot_points(MotionClip(sk, fps, root, local), roles), fps)
    frames = Rendered(local, root, contacts, np.zeros(n_out), local, root,
                      # no source motion to follow: every frame is a "new run", so a planted foot stays put
                      new_run=np.ones(n_out, dtype=bool))
    local, _ = lock_feet(sk, roles, frames, FootLockState(), fps=fps)
    local = keep_hands_out_of_head(sk, roles, local, root, fps)
    return MotionClip(sk, fps, root, local, contacts=contacts,
                      meta={"motifs": motifs, "grid_times_s": grid.times_s, "spread_cap": spread_cap,
                            "warp_rates": np.diff(src_s) * fps, "warp_anchors_s": anchors[0]})


def neural_fit(db: MotionDatabase, music: MusicFeatures, genre: str) -> StyleFit:
    """``fit_style``'s choice, unless it plays the style slower than ``RATE_RANGE``: then the best-sharing
    fit that plays it at least as fast as captured, on the song's beat or half time, if the genre has one.

    Why: the network's joint speed follows the rate it dances at on the slow side (tune split: p99 over
    the style's mocap 0.78 at rate 0.77, 0.83 at 0.82), with nothing to lift it, while on the fast side
    the beat warp's speed limit holds it near the mocap's (1.20 at 1.29). A 180 bpm song danced to
    salsa's half time (0.78) came out at 0.70-0.85 of the mocap's p99 by seed; on the beat, 1.05-1.10.
    Not double time: it makes the network dance twice the moves at the edge of the tempi it learned (tune
    split, a 90 bpm waltz: accent precision 0.40 -> 0.28, and its p99 at 0.78 was inside the guard).
    """
    fits = style_fits(db, np.diff(music.beat_times_s), genre, beat_in_bar=music.beat_in_bar)
    fit = equally_good(fits)[0]   # fit_style's choice, from the same list
    if fit.rate >= RATE_RANGE[0]:
        return fit
    faster = [f for f in fits if f.rate >= 1.0 and np.isscalar(f.subdivide) and f.subdivide <= 1]
    return max(faster, key=lambda f: f.share) if faster else fit


def dance(music: MusicFeatures, db: MotionDatabase, config, timings: dict,
          progress=None) -> tuple[MotionClip, EngineRun]:
    """The neural engine under the engine protocol (``engines.protocol``): choose style and model,
    generate, summarise."""
    t = time.perf_counter()
    if config.model is not None and not Path(config.model).is_file():
        raise InputError(f"--model {config.model}: no such file (a .pt written by 'dancesynth train')")
    chosen = load_model(config.model) if config.model is not None else None   # the user's: --model PATH
    genre = config.style or (chosen.genre if chosen is not None else DEFAULT_GENRE)
    fit = replace(neural_fit(db, music, genre), forced=config.style is not None)
    style, subdivide = fit.style, fit.subdivide
    model = chosen if chosen is not None else load_model(find_model(style.genre))
    if model.skeleton.names != style.skeleton.names:
        raise ModelError(f"the neural model {model.path} was trained on another skeleton than style "
                         f"'{style.name}'; retrain it with 'dancesynth train --style {style.genre}'")
    timings["prepare_s"] = time.perf_counter() - t
    t = time.perf_counter()
    grid = beat_grid(music, subdivide=subdivide)
    seed = 0 if config.seed is None else int(config.seed)
    motifs = motif_plan(grid.n_intervals, model.template, model.transitions, np.random.default_rng(seed))
    # A returning section replays its motifs (the network makes its own motion of them).
    form = form_plan(music, grid.times_s, config.repeat, config.vary)
    held = form.held(motifs)
    motifs = np.where(held >= 0, held, motifs)
    clip = generate(model, music, grid, motifs, fps=config.fps, seed=seed,
                    spread_cap=SPREAD_CAP if config.restore_spread else 1.0,
                    speed_limit=np.inf if WARP_SPEED_PERCENTILE is None else
                    SpeedRoom.of(cached_peak_speeds(style), WARP_SPEED_PERCENTILE).limit)
    if (form.source >= 0).any():   # the network makes its motion afresh: a replay shows the frames it made
        clip, frames = replay_motion(clip, grid.times_s, form)
        roles = find_roles(clip.skeleton)
        local, _ = lock_feet(clip.skeleton, roles, frames, FootLockState(), fps=config.fps)
        clip = replace(clip, local_rot=keep_hands_out_of_head(clip.skeleton, roles, local, clip.root_pos,
                                                              config.fps))
    timings["synthesis_s"] = time.perf_counter() - t
    # The generator makes its own motion (its warp rates are per frame): no beat pieces to count.
    run = EngineRun(style=style.name, genre=style.genre, style_fingerprint=style.fingerprint, subdivide=subdivide,
                    grid_times_s=grid.times_s, warp_rates=clip.meta["warp_rates"], step_s=(timings["synthesis_s"],),
                    motifs={"motif_plan": motifs}, fit=fit_summary(fit, music, None), form=form,
                    extra={"prepare_stage": "model", **model_id(model),
                           "spread_cap": clip.meta["spread_cap"], "form": form.summary(motifs),
                           "realtime_factor": music.duration_s / max(timings["synthesis_s"], 1e-9)})
    return clip, run
