"""Realism and diversity of generated dance: FID_k, FID_g, Div_k, Div_g.

The four numbers of Li et al. 2021 (*AI Choreographer*, AIST++), also reported by
Bailando and EDGE, computed on our BVH skeletons from the kinetic and geometric
features of ``eval.realism_features`` (re-exported here: ``kinetic_features``,
``geometric_features``, ``smpl_joint_map``, ``SMPL_JOINTS``, ``GEOMETRIC_FEATURES``):

- ``fid``: the Fréchet distance between Gaussians fitted to two feature sets.
- ``diversity``: the mean Euclidean distance between the pairs of a feature set.
- ``window_features``: both features on fixed windows cut from the motions.
- ``realism(generated, reference)``: all four, on fixed windows cut from the motions,
  with features normalised by the reference set's mean and standard deviation
  (Bailando's ``metrics_new.py``); ``realism_scores`` does the same for several
  generated sets against one reference, whose features it computes once.
- ``held_out_split(style)``: clips held out of a style, to be the reference that a
  dance made from the rest of the style never saw.

The numbers are **not comparable with AIST++ tables**: other skeletons, other
joints, other data, windows instead of whole sequences (see docs/metrics.md).

Pure functions: no files, no printing. Bad input raises ``InputError``.
"""

from __future__ import annotations

import re
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..types import MotionClip, Skeleton
from .motion_metrics import check_motion
from .realism_features import (FEATURE_FPS, GEOMETRIC_FEATURES, MIN_DURATION_S, SMPL_JOINTS, _geometric_layout,
                               _joint_positions, _kinetic, _relations, geometric_features, kinetic_features,
                               smpl_joint_map)

__all__ = ["FEATURE_FPS", "DEFAULT_WINDOW_S", "MIN_DURATION_S", "DEFAULT_FID_EPS", "GEOMETRIC_MIN_STD",
           "SMPL_JOINTS", "GEOMETRIC_FEATURES", "smpl_joint_map", "kinetic_features", "geometric_features",
           "window_features", "fid", "diversity", "normalise_features", "realism", "realism_scores",
           "held_out_split"]

#: Window length and default stride (half a window) that ``realism`` cuts motions into.
DEFAULT_WINDOW_S = 5.0
#: Ridge added to both covariances, relative to their mean variance (see ``fid``).
DEFAULT_FID_EPS = 1e-6
#: Smallest scale of a geometric feature in ``realism`` (a fraction of a window's frames):
#: about the sampling spread of a relation that occurs a few times in a 5 s window. Below
#: it, a relation the small reference set happens (almost) never to show would dominate FID_g.
GEOMETRIC_MIN_STD = 0.05
# Smallest scale of a kinetic feature: 1 % of its reference mean (rarely binding).
_KINETIC_MIN_STD_FRAC = 0.01


# ---------------------------------------------------------------------------------------------
# Windows


def _check_same_skeleton(motions: Sequence[MotionClip], name: str, skeleton: Skeleton | None = None) -> Skeleton:
    ref = skeleton or motions[0].skeleton
    for i, m in enumerate(motions):
        sk = m.skeleton
        if sk is not ref and (sk.names != ref.names or not np.array_equal(sk.parents, ref.parents)):
            raise InputError(
                f"{name}[{i}] is on another skeleton ({sk.n_joints} joints: {', '.join(sk.names[:4])}, ...) than "
                f"the first motion ({ref.n_joints} joints: {', '.join(ref.names[:4])}, ...): realism compares "
                "motions of one skeleton (one style) at a time; retarget them first or compare per style")
    return ref


def _window_bounds(n_frames: int, window_s: float, stride_s: float) -> list[tuple[int, int]]:
    size = int(round(window_s * FEATURE_FPS)) + 1  # frames spanning window_s
    step = max(1, int(round(stride_s * FEATURE_FPS)))
    return [(a, a + size) for a in range(0, n_frames - size + 1, step)]


def window_features(motions: Sequence[MotionClip], *, window_s: float = DEFAULT_WINDOW_S,
                    stride_s: float | None = None, name: str = "motions") -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Kinetic and geometric features of every window of ``motions`` (one skeleton).

    Each motion is resampled to 60 fps and cut into windows of ``window_s`` seconds
    every ``stride_s`` (default ``window_s / 2``); a window's kinetic features are
    those of its frames alone, its geometric features the mean of the motion's
    per-frame relations over its frames. Motions shorter than one window give none.
    Returns ``(kinetic (N, Dk), geometric (N, Dg), windows per motion)``.
    """
    window_s, stride_s = _check_window(window_s, stride_s)
    motions = _check_motions(motions, name)
    _check_same_skeleton(motions, name)
    joints, column, units = _geometric_layout(motions[0].skeleton)
    kin, geo, counts = [], [], []
    for m in motions:
        if m.n_frames < 4 or m.duration_s < window_s - 1e-9:
            counts.append(0)
            continue
        pos = _joint_positions(m, joints)
        bounds = _window_bounds(len(pos), window_s, stride_s)
        counts.append(len(bounds))
        if not bounds:
            continue
        rel = _relations(pos, column, units)
        kin += [_kinetic(pos[a:b]) for a, b in bounds]
        geo += [rel[a:b].mean(axis=0) for a, b in bounds]
    dk, dg = 3 * len(joints), len(GEOMETRIC_FEATURES)
    return (np.array(kin).reshape(-1, dk), np.array(geo, dtype=np.float64).reshape(-1, dg), counts)


def _check_window(window_s, stride_s) -> tuple[float, float]:
    try:
        window_s = float(window_s)
        stride_s = window_s / 2.0 if stride_s is None else float(stride_s)
    except (TypeError, ValueError):
        raise InputError(f"window_s and stride_s must be numbers of seconds, got {window_s!r}, {stride_s!r}") from None
    if not (np.isfinite(window_s) and window_s >= MIN_DURATION_S):
        raise InputError(f"window_s = {window_s} s: use a window of at least {MIN_DURATION_S} s (5 s is usual)")
    if not (np.isfinite(stride_s) and stride_s > 0):
        raise InputError(f"stride_s = {stride_s} s: use a positive stride (e.g. half the window)")
    return window_s, stride_s


def _check_motions(motions, name: str) -> list[MotionClip]:
    if isinstance(motions, MotionClip):
        raise InputError(f"{name} must be a list of MotionClips; wrap a single motion as [motion]")
    try:
        motions = list(motions)
    except TypeError:
        raise InputError(f"{name} must be a list of MotionClips, got {type(motions).__name__}") from None
    if not motions:
        raise InputError(f"{name} is empty: pass at least one MotionClip")
    for i, m in enumerate(motions):
        check_motion(m, f"{name}[{i}]")
    return motions


# ---------------------------------------------------------------------------------------------
# FID and diversity


def _feature_matrix(x, name: str, min_rows: int) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] == 0:
        raise InputError(f"{name} must be a (samples, dimensions) matrix, got shape {x.shape}")
    if len(x) < min_rows:
        raise InputError(f"{name} has {len(x)} sample(s); at least {min_rows} are needed "
                         "(use more or longer motions, or a shorter window)")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} has NaN or infinite values (row {int(np.argwhere(~np.isfinite(x))[0][0])})")
    return x


def fid(features_a, features_b, *, eps: float = DEFAULT_FID_EPS) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets (N, D) and (M, D).

    ``|μa − μb|² + tr(Σa + Σb − 2 (Σa Σb)^½)`` with unbiased covariances. With fewer
    samples than dimensions a covariance is singular: both get a ridge ``eps`` times
    their mean variance (the same on both sides, so identical sets still score 0), and
    ``tr (Σa Σb)^½`` is computed as ``tr (Σa^½ Σb Σa^½)^½`` (``scipy.linalg.sqrtm``, then
    the eigenvalues of a symmetric matrix), which stays real and non-negative. FID from
    few samples is biased upwards; compare numbers made with the same set sizes.
    """
    from scipy.linalg import sqrtm

    a = _feature_matrix(features_a, "features_a", 2)
    b = _feature_matrix(features_b, "features_b", 2)
    if a.shape[1] != b.shape[1]:
        raise InputError(f"feature sets differ in dimension ({a.shape[1]} vs {b.shape[1]}): "
                         "compute both with the same feature function on the same skeleton")
    if not (np.isfinite(eps) and eps >= 0):
        raise InputError(f"eps = {eps}: the covariance ridge must be a non-negative number")
    d = a.shape[1]
    cov_a, cov_b = np.cov(a, rowvar=False).reshape(d, d), np.cov(b, rowvar=False).reshape(d, d)
    mean_var = (np.trace(cov_a) + np.trace(cov_b)) / (2 * d)
    ridge = eps * (mean_var if mean_var > 0 else 1.0)  # two constant sets: any ridge cancels out
    cov_a = cov_a + ridge * np.eye(d)
    cov_b = cov_b + ridge * np.eye(d)
    root_a = np.real(sqrtm(cov_a))
    root_a = 0.5 * (root_a + root_a.T)
    inner = root_a @ cov_b @ root_a
    cross = np.sum(np.sqrt(np.clip(np.linalg.eigvalsh(0.5 * (inner + inner.T)), 0.0, None)))
    diff = a.mean(axis=0) - b.mean(axis=0)
    return float(max(diff @ diff + np.trace(cov_a) + np.trace(cov_b) - 2.0 * cross, 0.0))


def diversity(features) -> float:
    """Mean Euclidean distance over all pairs of rows of ``features`` (N, D); NaN for one row.

    Div_k / Div_g of Li et al. 2021 (Bailando's ``calculate_avg_distance``): how far
    apart the samples of one set lie, in the units of the (normalised) features.
    """
    from scipy.spatial.distance import pdist

    x = _feature_matrix(features, "features", 1)
    return float(np.mean(pdist(x))) if len(x) > 1 else float("nan")


def normalise_features(reference, *others, mode: str = "reference", min_std=1e-9):
    """Standardise feature sets with one mean and scale; returns the reference and the others.

    ``mode="reference"`` (default, as Bailando's ``metrics_new.py``): the reference
    set's mean and standard deviation, so every generated set is measured in the same
    units and the reference's own numbers do not depend on what it is compared with.
    ``"combined"``: the mean and standard deviation of all sets together. ``"none"``:
    unchanged. The scale is at least ``min_std`` (a number or one per dimension), so
    a dimension that is (nearly) constant in the reference — a relation the reference
    never shows — counts in units of ``min_std`` instead of dividing by zero.
    """
    ref = _feature_matrix(reference, "reference features", 1)
    rest = [_feature_matrix(o, "features", 1) for o in others]
    if any(o.shape[1] != ref.shape[1] for o in rest):
        raise InputError("feature sets differ in dimension: compute them on the same skeleton")
    if mode == "none":
        return (ref, *rest)
    if mode not in ("reference", "combined"):
        raise InputError(f"unknown normalisation '{mode}': use 'reference', 'combined' or 'none'")
    floor = np.broadcast_to(np.asarray(min_std, dtype=np.float64), ref.shape[1:])
    if not np.all(floor > 0):
        raise InputError(f"min_std must be positive, got {min_std!r}")
    basis = ref if mode == "reference" else np.vstack([ref, *rest])
    mean = basis.mean(axis=0)
    scale = np.maximum(basis.std(axis=0), floor)
    return tuple((x - mean) / scale for x in (ref, *rest))


def realism(generated: Sequence[MotionClip], reference: Sequence[MotionClip], *,
            window_s: float = DEFAULT_WINDOW_S, stride_s: float | None = None, normalise: str = "reference",
            geometric_min_std: float = GEOMETRIC_MIN_STD, eps: float = DEFAULT_FID_EPS) -> dict:
    """FID_k, FID_g, Div_k, Div_g of ``generated`` motions against ``reference`` motions of one skeleton.

    Both lists are cut into windows of ``window_s`` seconds every ``stride_s`` (default
    half a window) — our dances and clips are few and long, and the Gaussians need
    many samples; a motion shorter than one window is left out (counted in
    ``skipped_*``). Features are normalised (``normalise_features``, default by the
    reference windows' mean and standard deviation, a geometric feature's scale at
    least ``geometric_min_std``, a kinetic one's at least 1 % of its mean), then::

        fid_k, fid_g   = fid(generated, reference) on kinetic / geometric features
        div_k, div_g   = diversity(generated windows)
        div_k_ref, ... = diversity(reference windows), the level real motion shows

    ``n_generated`` / ``n_reference`` count windows (overlapping windows are not
    independent samples). Raises ``InputError`` for empty lists, motions of different
    skeletons, NaN, or fewer than 2 windows on a side.
    Not comparable with AIST++ tables: other skeletons, joints, data and windows.
    """
    return realism_scores({"generated": generated}, reference, window_s=window_s, stride_s=stride_s,
                          normalise=normalise, geometric_min_std=geometric_min_std, eps=eps)["generated"]


def realism_scores(generated: Mapping[str, Sequence[MotionClip]], reference: Sequence[MotionClip], *,
                   window_s: float = DEFAULT_WINDOW_S, stride_s: float | None = None, normalise: str = "reference",
                   geometric_min_std: float = GEOMETRIC_MIN_STD, eps: float = DEFAULT_FID_EPS) -> dict[str, dict]:
    """``realism`` of several generated sets against one reference: ``{name: realism(generated[name], reference)}``.

    The same numbers as ``realism`` set by set, but the reference windows' features are
    computed once (a table of engines against one held-out reference). ``generated``
    maps a name of the caller's choosing to a list of motions; every motion of every
    set must be on the reference's skeleton. Raises ``InputError`` as ``realism`` does,
    naming the set at fault.
    """
    window_s, stride_s = _check_window(window_s, stride_s)
    if not isinstance(generated, Mapping) or not generated:
        raise InputError("generated must be a non-empty dict {name: [MotionClip, ...]}; for one list use realism()")
    sets = {}
    for key, motions in generated.items():
        label = "generated" if len(generated) == 1 else f"generated[{key!r}]"
        sets[key] = (label, _check_motions(motions, label))
    reference = _check_motions(reference, "reference")
    skeleton = _check_same_skeleton(reference, "reference")
    for label, motions in sets.values():
        _check_same_skeleton(motions, label, skeleton)
    ref_k, ref_g, ref_n = window_features(reference, window_s=window_s, stride_s=stride_s, name="reference")
    _enough_windows("reference", len(ref_k), window_s, stride_s)
    kinetic_floor = _KINETIC_MIN_STD_FRAC * np.abs(ref_k.mean(axis=0)) + 1e-9
    joints = list(smpl_joint_map(skeleton))
    out = {}
    for key, (label, motions) in sets.items():
        gen_k, gen_g, gen_n = window_features(motions, window_s=window_s, stride_s=stride_s, name=label)
        _enough_windows(label, len(gen_k), window_s, stride_s)
        rk, gk = normalise_features(ref_k, gen_k, mode=normalise, min_std=kinetic_floor)
        rg, gg = normalise_features(ref_g, gen_g, mode=normalise, min_std=geometric_min_std)
        out[key] = {
            "fid_k": fid(gk, rk, eps=eps), "fid_g": fid(gg, rg, eps=eps),
            "div_k": diversity(gk), "div_g": diversity(gg),
            "div_k_ref": diversity(rk), "div_g_ref": diversity(rg),
            "n_generated": int(len(gk)), "n_reference": int(len(rk)),
            "skipped_generated": int(sum(c == 0 for c in gen_n)),
            "skipped_reference": int(sum(c == 0 for c in ref_n)),
            "dim_k": int(gk.shape[1]), "dim_g": int(gg.shape[1]),
            "window_s": window_s, "stride_s": stride_s, "normalise": normalise,
            "geometric_min_std": geometric_min_std, "joints": joints,
        }
    return out


def _enough_windows(name: str, n: int, window_s: float, stride_s: float) -> None:
    if n < 2:
        raise InputError(f"{name} motions give {n} window(s) of {window_s:g} s (stride {stride_s:g} s); at least "
                         f"2 are needed: pass longer or more motions, or a shorter window_s")


# ---------------------------------------------------------------------------------------------
# Held-out reference


def _take_key(name: str, n_frames: int):
    """Clips of one take: CMU partners (60_01 and 61_01, recorded together, same length) share a key."""
    m = re.match(r"^\d+_(\d+)", name)
    return ("take", m.group(1), n_frames) if m else ("clip", name)


def held_out_split(style, *, fraction: float = 0.2, n_clips: int | None = None, seed: int = 0,
                   min_remaining: int = 2, by_take: bool = True):
    """Hold clips of ``style`` out: ``(style without them, [held-out MotionClips])``.

    About ``fraction`` of the clips (at least one), or exactly ``n_clips`` when given
    (at least that many with ``by_take``), chosen by a seeded shuffle, so the same
    seed gives the same split. With ``by_take`` the partners of one take (CMU salsa
    60_xx and 61_xx with the same trial number and length: two dancers recorded
    together) go out together, so a held-out clip's partner does not stay behind.
    At least ``min_remaining`` clips stay for the style to dance on; a style too small
    for that raises ``InputError``. Held-out clips come in the style's clip order.
    """
    total = style.n_clips
    if n_clips is None:
        if not (0.0 < float(fraction) < 1.0):
            raise InputError(f"fraction = {fraction}: hold out a fraction between 0 and 1 (e.g. 0.2)")
        want = max(1, int(round(fraction * total)))
    else:
        if int(n_clips) != n_clips or n_clips < 1:
            raise InputError(f"n_clips = {n_clips}: hold out a positive whole number of clips")
        want = int(n_clips)
    if not min_remaining >= 1:
        raise InputError(f"min_remaining = {min_remaining}: at least one clip must stay in the style")
    if total - want < min_remaining:
        raise InputError(f"style '{style.name}' has {total} clip(s): holding out {want} would leave fewer than "
                         f"{min_remaining} to dance on; use a larger style or hold out fewer clips")
    groups: dict = {}
    for i in range(total):
        n = int(style.clip_starts[i + 1] - style.clip_starts[i])
        key = _take_key(style.clip_names[i], n) if by_take else ("clip", i)
        groups.setdefault(key, []).append(i)
    order = list(groups.values())
    rng = np.random.default_rng(seed)
    held: list[int] = []
    for g in (order[k] for k in rng.permutation(len(order))):
        if len(held) >= want:
            break
        if total - len(held) - len(g) >= min_remaining:
            held += g
    if len(held) < want:
        raise InputError(f"style '{style.name}': cannot hold out {want} clip(s) while keeping {min_remaining} and "
                         "the partners of a take together; hold out fewer clips or pass by_take=False")
    held.sort()
    reference = [style.clip(i) for i in held]
    reduced = style
    for i in reversed(held):  # from the end, so the remaining indices stay valid
        reduced = reduced.without_clip(i)
    return reduced, reference
