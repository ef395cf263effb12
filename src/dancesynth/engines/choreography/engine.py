"""``dance --engine choreography``: song -> beat grid -> one motif per beat -> real words, stitched.

Aristidou et al.'s global structure without the learned pose generator: the
choreography level (``level.py``, eq. 5) chooses a motif per beat so the dance's
signature follows its genre's template -- or follows the user's constraints
(``--motif-at``) or a reference dance's motif sequence (``--recreate``, §5.5.1) --
and the mixer (``mixer.py``, §5.2.5) dances each motif with a real word of the
style's mocap, time-scaled to the beat.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ...errors import InputError
from ...motion.database import MotionDatabase, Style
from ...motion.motifs import chi2, parse_motif_id
from ...motion.words import clip_words
from ...provenance import EngineRun
from ...types import MotionClip, MusicFeatures
from ..beatgrid import StyleFit, beat_grid, fit_style, fit_summary
from ..form import form_plan
from ..timing import plain_timing
from .level import constraint_beats, parse_motif_at, plan_motifs, recreate_plan
from .mixer import MixerConfig, mix, substitute_motifs, word_bank

_BANKS: dict = {}  # (style, model) -> WordBank: cutting and embedding a style's words takes seconds


def style_bank(style: Style, model, accent_window: float = 0.0):
    key = (style.name, style.fingerprint, style.n_frames, model.k, hash(np.asarray(model.centroids).tobytes()),
           accent_window)
    if key not in _BANKS:
        _BANKS.clear()  # one at a time: a bank holds every word of a style
        _BANKS[key] = word_bank(style, model, accent_window)
    return _BANKS[key]


@dataclass(frozen=True)
class Reference:
    """A reference dance for re-creation: its motif per word, the genre its signature is nearest,
    and the styles on its skeleton."""

    path: str
    motifs: np.ndarray
    genre: str
    styles: tuple[Style, ...]


def reference_motifs(clip: MotionClip, path: str, model, styles) -> Reference:
    """Check a reference dance (read from ``path``) is on the skeleton of one of ``styles``, cut it
    into words at its kinematic beats (as ``dancesynth motifs`` does) and assign each word its motif.

    ``InputError`` if it is on another skeleton or too short for a word.
    """
    names = tuple(clip.skeleton.names)
    same = tuple(s for s in styles if tuple(s.skeleton.names) == names)
    if not same:
        skeletons = sorted({f"{s.skeleton.n_joints} joints ({s.name})" for s in styles})
        raise InputError(f"the reference {path} is on a skeleton of {len(names)} joints ({', '.join(names[:4])}, "
                         f"...) that no style uses ({'; '.join(skeletons)}): re-create from a dance captured "
                         "on one of those skeletons")
    ids = model.assign(clip_words(clip).features)
    return Reference(str(path), ids, model.nearest_genre(model.signature(ids)), same)


def _choose(db: MotionDatabase, music: MusicFeatures, name: str | None, ref: Reference | None) -> StyleFit:
    """The style and metrical level to dance: the least time warp (``fit_style``), on the reference's
    skeleton and genre when re-creating."""
    if ref is None:
        return fit_style(db, music, name)
    same = list(ref.styles)
    if name is None and any(s.genre == ref.genre for s in same):
        same = [s for s in same if s.genre == ref.genre]
    return replace(fit_style(MotionDatabase({s.name: s for s in same}, db.source), music), forced=name is not None)


def _check_constraints(fixed: dict, bank, style: Style) -> None:
    missing = sorted({m for m in fixed.values() if not np.any(bank.motif == m)})
    if missing:
        raise InputError(f"style '{style.name}' has no word of motif {', '.join(f'M{m}' for m in missing)}; "
                         f"its motifs are {', '.join(f'M{m}' for m in np.unique(bank.motif))} -- choose one of "
                         "those or another --style ('dancesynth motifs' shows a dance's motifs)")


def dance(music: MusicFeatures, db: MotionDatabase, config, timings: dict,
          progress=None) -> tuple[MotionClip, EngineRun]:
    """The choreography engine under the engine protocol (``engines.protocol``): the database's motif
    model and ``config.recreate``'s reference dance loaded, then ``choreography_dance``."""
    from ...motion.motifs import load_motif_model

    t = time.perf_counter()
    reference = None
    if config.recreate is not None:
        from ...io.bvh import read_bvh

        reference = read_bvh(config.recreate)
    model = load_motif_model(db)
    loaded_s = time.perf_counter() - t
    clip, run = choreography_dance(music, db, config, timings=timings, motif_model=model, reference=reference)
    timings["prepare_s"] += loaded_s
    return clip, run


def choreography_dance(music: MusicFeatures, db: MotionDatabase, config, *, timings: dict, motif_model,
                       reference: MotionClip | None = None,
                       mixer: MixerConfig = MixerConfig()) -> tuple[MotionClip, EngineRun]:
    """``api.dance`` for ``config.engine == "choreography"``.

    ``config`` is a ``DanceConfig``: ``motif_at`` (``"12.0=M17"`` strings or ``(seconds,
    motif)`` pairs) and ``recreate`` (a reference BVH path, read into ``reference``) are the
    user's constraints; ``motif_model`` the database's (``motion.motifs.load_motif_model``).
    """
    t = time.perf_counter()
    if not config.accent_timing:
        mixer = plain_timing(mixer)
    model = motif_model
    pool = db.styles_of(config.style) if config.style else list(db.styles.values())
    ref = reference_motifs(reference, str(config.recreate), model, pool) if reference is not None else None
    constraints = [parse_motif_at(c, model.k) if isinstance(c, str)
                   else (float(c[0]), parse_motif_id(str(c[1]), model.k)) for c in config.motif_at]
    fit = _choose(db, music, config.style, ref)
    style, subdivide = fit.style, fit.subdivide
    bank = style_bank(style, model, mixer.accent_window)
    timings["prepare_s"] = time.perf_counter() - t

    t = time.perf_counter()
    grid = beat_grid(music, subdivide=subdivide)
    n = grid.n_intervals
    rng = np.random.default_rng(0 if config.seed is None else int(config.seed))
    fixed = constraint_beats(constraints, grid.times_s, music.duration_s)
    _check_constraints(fixed, bank, style)
    if ref is not None:  # the reference's sequence; --motif-at beats, if any, override it
        plan = recreate_plan(ref.motifs, n)
        plan[list(fixed)] = list(fixed.values())
        # Its words as typical of their motifs as they come: a pace away from the style's mean is the
        # reference's to keep (found again in the motion 0.62 with the pace cost, 0.87 without).
        mixer = replace(mixer, speed_weight=0.0)
    else:
        plan = plan_motifs(n, model.templates[style.genre], model.transitions[style.genre], rng, fixed=fixed)
    danced = substitute_motifs(bank, model.centroids)[plan]
    free = np.full(n, ref is None)  # a re-creation and the user's constraints are danced as planned
    free[list(fixed)] = False
    # A returning section replays its motifs and words (a re-creation follows its reference's form
    # instead); the user's --motif-at beats stay theirs.
    form = form_plan(music, grid.times_s, config.repeat if ref is None else "off", config.vary)
    if fixed:
        form = replace(form, source=np.where(np.isin(np.arange(len(form.source)), list(fixed)), -1, form.source))
    held = form.held(plan)
    plan = np.where(held >= 0, held, plan)
    result = mix(style, bank, danced, grid.times_s, music.duration_s, fps=config.fps, rng=rng, config=mixer,
                 beat_count=grid.count, bar_position=grid.bar_position, beats_per_bar=grid.beats_per_bar,
                 free=free, form=form)
    timings["synthesis_s"] = time.perf_counter() - t
    p = result.pieces
    jumps = p.t0[p.jump]
    jumps = jumps[(jumps >= 0.0) & (jumps < music.duration_s)]
    warp_rates = (p.f1 - p.f0) / (p.t1 - p.t0) / style.fps
    extra = {"prepare_stage": "motifs", "motifs": model.k,
             "motif_chi2": chi2(model.templates[style.genre], model.signature(result.motifs)),
             "plan_followed": float(np.mean(result.motifs == plan)), "constraints": len(fixed),
             "recreate": None if ref is None else ref.path,
             "form": form.summary(result.words)}
    motifs = {"motif_ids": result.motifs, "motif_plan": plan,
              "motif_constraints": {int(b): int(m) for b, m in fixed.items()},
              "word_frames": np.stack([p.f0, p.f1], axis=1).astype(np.int64)}
    run = EngineRun(style=style.name, genre=style.genre, style_fingerprint=style.fingerprint, subdivide=subdivide,
                    grid_times_s=grid.times_s, transition_times_s=jumps, warp_rates=warp_rates,
                    step_s=(timings["synthesis_s"],), source_frames=result.source_frames, motifs=motifs,
                    fit=fit_summary(fit, music, warp_rates), extra=extra, form=form)
    clip = MotionClip(style.skeleton, config.fps, result.root_pos, result.local_rot, contacts=result.contacts)
    return clip, run
