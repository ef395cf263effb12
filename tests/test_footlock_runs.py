"""The foot lock computes whole runs of frames at once: the same corrections, weights and state, to
the bit, as stepping its state machine frame by frame (the reference below, the pass as it was)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from dancesynth.engines.footlock import FootLockState, LockParams, _released, _track_foot


def track_frame_by_frame(f: dict, contacts, new_run, ankle, raw, fps: float, p: LockParams):
    n = len(ankle)
    delta, weight = np.zeros((n, 3)), np.zeros(n)
    grip, ease = max(p.grip_s * fps, 1.0), max(p.ease_s * fps, 1.0)
    for t in range(n):
        if contacts[t]:
            if not f["locked"]:
                carry = _released(f["release_x0"], f["release_v0"], f["release_at"] + 1, f["release_len"], fps) \
                    if f["release_len"] else 0.0
                f.update(locked=1.0, target=ankle[t] + carry, release_len=0.0, held=0.0)
            else:
                f["held"] += 1.0
                own = 0.0 if new_run[t] else p.follow_source * (raw[t] - f["raw_prev"])
                slip = max(0.0, 1.0 - f["held"] / grip)
                f["target"] = f["target"] + own + slip * (ankle[t] - f["ankle_prev"] - own)
            f["target"][1] = ankle[t, 1]
            delta[t] = f["target"] - ankle[t]
            size = np.linalg.norm(delta[t])
            if size > p.max_offset_m:
                delta[t] *= p.max_offset_m / size
                f["target"] = ankle[t] + delta[t]
            goal = 1.0
        else:
            if f["locked"]:
                x0, vel = f["applied"], f["applied_vel"]
                size = np.linalg.norm(x0)
                length = max(p.release_s, size / p.release_speed_m_s) * fps
                v0 = vel * min(1.0, size / (length / fps) / max(np.linalg.norm(vel), 1e-9))
                f.update(locked=0.0, release_x0=x0, release_v0=v0, release_at=0.0, release_len=length)
            goal = 0.0
            if f["release_len"]:
                f["release_at"] += 1.0
                delta[t] = _released(f["release_x0"], f["release_v0"], f["release_at"], f["release_len"], fps)
                goal = min(1.0, (f["release_len"] - f["release_at"]) / ease)
                if f["release_at"] >= f["release_len"]:
                    f["release_len"] = 0.0
        f["weight"] = float(np.clip(goal, f["weight"] - 1.0 / ease, f["weight"] + 1.0 / ease))
        weight[t] = f["weight"]
        f["applied_vel"], f["applied"] = (delta[t] - f["applied"]) * fps, delta[t]
        f["raw_prev"], f["ankle_prev"] = raw[t], ankle[t]
    return delta, weight


def _fresh_foot() -> dict:
    state = FootLockState()
    return {f.name: (getattr(state, f.name)[0].copy() if getattr(state, f.name).ndim > 1
                     else float(getattr(state, f.name)[0])) for f in fields(FootLockState)}


def _same(a, b) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


@pytest.mark.parametrize("follow_source", [0.0, 0.5, 1.0])
def test_runs_at_once_equal_the_frame_by_frame_state_machine(follow_source):
    rng = np.random.default_rng(int(follow_source * 10))
    for trial in range(60):
        p = LockParams(follow_source=follow_source, grip_s=float(rng.choice([0.1, 0.0, 0.3])),
                       max_offset_m=float(rng.choice([0.1, 0.02, 1.0])), release_s=float(rng.choice([0.2, 0.05])),
                       ease_s=float(rng.choice([0.15, 0.0, 0.5])))
        fps = float(rng.choice([30.0, 25.0, 60.0]))
        reference, fast = _fresh_foot(), _fresh_foot()
        for call in range(3):  # the state carries from call to call, as between streaming segments
            n = int(rng.integers(1, 120))
            contacts = (rng.random(n) < 0.5 if trial % 5 == 0  # labels that flicker
                        else np.resize(np.repeat(rng.random(30) < 0.6, rng.integers(1, 25)), n))
            new_run = rng.random(n) < 0.05
            step = float(rng.choice([0.002, 0.02]))  # 0.02 m a frame: corrections past max_offset_m
            ankle = np.cumsum(rng.normal(scale=step, size=(n, 3)), axis=0) + rng.normal(size=3)
            raw = ankle + np.cumsum(rng.normal(scale=0.003, size=(n, 3)), axis=0)
            d1, w1 = track_frame_by_frame(reference, contacts, new_run, ankle, raw, fps, p)
            d2, w2 = _track_foot(fast, contacts, new_run, ankle, raw, fps, p)
            assert _same(d1, d2) and _same(w1, w2)
            assert all(_same(reference[k], fast[k]) for k in reference)
