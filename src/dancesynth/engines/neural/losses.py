"""Losses of §4.4: geodesic rotation loss and forward-kinematics positions (eq. 6), foot contacts,
the motion perceptual loss through the frozen word embedding (eq. 9, against the motif), and a
penalty on hands inside the head.

All work on un-normalised pose vectors (``data.encode_pose``) in torch, batched as
(B, T, P). Positions are computed in each frame's heading frame with the root above
the origin (the trajectory is learned through the root speeds); the perceptual loss
integrates the trajectory, as words see the root's motion.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ...motion.roles import find_roles
from ...types import Skeleton
from .data import ROOT_DIMS


def six_to_matrix(six: torch.Tensor) -> torch.Tensor:
    """(..., 6) -> (..., 3, 3): Gram-Schmidt on the two stored columns (as ``data.six_to_matrix``)."""
    a, b = six[..., 0::2], six[..., 1::2]
    x = F.normalize(a, dim=-1, eps=1e-8)
    y = F.normalize(b - (x * b).sum(-1, keepdim=True) * x, dim=-1, eps=1e-8)
    return torch.stack([x, y, torch.cross(x, y, dim=-1)], dim=-1)


def fk(local_mats: torch.Tensor, root_pos: torch.Tensor, offsets: torch.Tensor, parents) -> tuple:
    """Global rotation matrices (..., J, 3, 3) and positions (..., J, 3), as ``kinematics.fk``."""
    g_rot, g_pos = [], []
    for j, p in enumerate(parents):
        if p < 0:
            g_rot.append(local_mats[..., j, :, :])
            g_pos.append(root_pos)
            continue
        g_rot.append(g_rot[p] @ local_mats[..., j, :, :])
        g_pos.append(g_pos[p] + (g_rot[p] @ offsets[j].unsqueeze(-1)).squeeze(-1))
    return torch.stack(g_rot, dim=-3), torch.stack(g_pos, dim=-2)


def yaw_matrix(yaw: torch.Tensor) -> torch.Tensor:
    """Rotations about +Y (..., 3, 3)."""
    c, s, z, o = torch.cos(yaw), torch.sin(yaw), torch.zeros_like(yaw), torch.ones_like(yaw)
    return torch.stack([torch.stack([c, z, s], -1), torch.stack([z, o, z], -1),
                        torch.stack([-s, z, c], -1)], dim=-2)


def geodesic(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle (radians) between rotation matrices; the geodesic distance of their quaternions."""
    cos = ((a.transpose(-1, -2) @ b).diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    return torch.acos(cos.clamp(-1.0 + 1e-6, 1.0 - 1e-6))


class Body:
    """What the losses need of a skeleton, as tensors."""

    def __init__(self, skeleton: Skeleton, fps: float):
        self.n_joints = skeleton.n_joints
        self.parents = [int(p) for p in skeleton.parents]
        self.offsets = torch.as_tensor(np.asarray(skeleton.offsets), dtype=torch.float32)
        roles = find_roles(skeleton)
        self.ankles = list(roles.ankles)
        self.head, self.wrists = int(roles.head), [int(w) for w in roles.wrists if w >= 0]
        self.fps = fps

    def split(self, poses: torch.Tensor):
        """Pose vectors -> local matrices (..., J, 3, 3), root (..., 4), contacts (..., 2)."""
        j = self.n_joints
        six = poses[..., :6 * j].reshape(*poses.shape[:-1], j, 6)
        return six_to_matrix(six), poses[..., 6 * j:6 * j + ROOT_DIMS], poses[..., 6 * j + ROOT_DIMS:]

    def local_positions(self, mats: torch.Tensor, root: torch.Tensor):
        """FK in each frame's heading frame, the root at (0, height, 0)."""
        z = torch.zeros_like(root[..., 3])
        return fk(mats, torch.stack([z, root[..., 3], z], -1), self.offsets.to(mats.device), self.parents)

    def world_positions(self, mats: torch.Tensor, root: torch.Tensor):
        """Global rotations and positions (B, T, J, ...) with the trajectory integrated from frame 0."""
        dt = 1.0 / self.fps
        yaw = torch.cumsum(root[..., 2] * dt, dim=-1) - root[..., :1, 2] * dt
        prev_yaw = torch.cat([yaw[..., :1], yaw[..., :-1]], dim=-1)
        step = torch.stack([root[..., 1], torch.zeros_like(yaw), root[..., 0]], -1) * dt
        step = (yaw_matrix(prev_yaw) @ step.unsqueeze(-1)).squeeze(-1)
        step = torch.cat([torch.zeros_like(step[..., :1, :]), step[..., 1:, :]], dim=-2)
        xz = torch.cumsum(step, dim=-2)
        root_pos = torch.stack([xz[..., 0], root[..., 3], xz[..., 2]], -1)
        heading = yaw_matrix(yaw).unsqueeze(-3)
        mats = torch.cat([heading @ mats[..., :1, :, :], mats[..., 1:, :, :]], dim=-3)
        return fk(mats, root_pos, self.offsets.to(mats.device), self.parents)


def word_features(pos: torch.Tensor, root_mats: torch.Tensor, fps: float, words: torch.Tensor) -> torch.Tensor:
    """``motion.words.features_at`` in torch: features (N, 13, D) of words cut from a batch.

    ``pos`` (B, T, 14, 3) global landmark positions, ``root_mats`` (B, T, 3, 3) global
    root rotations, ``words`` (N, 3): batch index, first and last frame (fractional,
    inclusive) of each word. Samples are linear in time; the heading is the root's
    at the rounded first sample; root velocity by central differences in m/s.
    """
    from ...motion.words import WORD_FRAMES

    b = words[:, 0].long()
    u = torch.linspace(0.0, 1.0, WORD_FRAMES, dtype=pos.dtype, device=pos.device)
    times = (words[:, 1:2] + (words[:, 2:3] - words[:, 1:2]) * u).clamp(0, pos.shape[1] - 1)   # (N, 13)
    lo = times.floor().long().clamp(max=pos.shape[1] - 2)
    a = (times - lo)[..., None, None]
    sampled = pos[b[:, None], lo] * (1 - a) + pos[b[:, None], lo + 1] * a                     # (N, 13, 14, 3)
    forward = root_mats[b, torch.round(times[:, 0]).long()][..., :, 2]                          # local +Z, world
    inv_heading = yaw_matrix(-torch.atan2(forward[..., 0], forward[..., 2]))                    # (N, 3, 3)
    rel = (inv_heading[:, None, None] @ (sampled - sampled[:, :, :1]).unsqueeze(-1)).squeeze(-1)
    root, t = sampled[:, :, 0], times / fps
    pad_x = torch.cat([root[:, :1], root, root[:, -1:]], dim=1)
    pad_t = torch.cat([t[:, :1], t, t[:, -1:]], dim=1)
    vel = (pad_x[:, 2:] - pad_x[:, :-2]) / (pad_t[:, 2:] - pad_t[:, :-2]).clamp(min=1e-9).unsqueeze(-1)
    vel = (inv_heading[:, None] @ vel.unsqueeze(-1)).squeeze(-1)
    return torch.cat([rel.flatten(2), vel], dim=-1)


class Perceptual(nn.Module):
    """Motion perceptual loss (eq. 9): squared distance of each generated word's embedding to its motif.

    The motif is the centroid of the word's ground-truth motif cluster in the frozen
    embedding of the motif model (``MotifModel.centroids``), as the paper compares the
    output word with the motif, not with the real word (the rotation and position
    terms already do that).
    """

    def __init__(self, body: Body, landmarks, embed: nn.Module, centroids):
        super().__init__()
        self.body, self.landmarks, self.embed = body, [int(i) for i in landmarks], embed
        self.register_buffer("centroids", torch.as_tensor(np.asarray(centroids), dtype=torch.float32))
        for p in self.embed.parameters():
            p.requires_grad_(False)

    def features(self, poses: torch.Tensor, words: torch.Tensor) -> torch.Tensor:
        mats, root, _ = self.body.split(poses)
        g_rot, g_pos = self.body.world_positions(mats, root)
        return word_features(g_pos[..., self.landmarks, :], g_rot[..., 0, :, :], self.body.fps, words)

    def forward(self, pred: torch.Tensor, words: torch.Tensor) -> torch.Tensor:
        """``words`` (N, 4): batch index, first and last frame, motif id (words without a motif are skipped)."""
        words = words[words[:, 3] >= 0]
        if len(words) == 0:
            return pred.new_zeros(())
        z = self.embed(self.features(pred, words[:, :3]).float())
        return (z - self.centroids[words[:, 3].long()]).pow(2).sum(-1).mean()


class PoseLoss(nn.Module):
    """Weighted sum of the §4.4 terms; ``forward`` returns (total, {name: value})."""

    HEAD_RADIUS_M = 0.2   # hands nearer the head joint than this (or than the real hand) are pushed out
    KINETIC_FLOOR = (0.01, 0.01, 0.1)   # m²/s², m²/s², m/s²: a still joint's statistics do not blow up the log

    def __init__(self, body: Body, mean, std, config, perceptual=None):
        super().__init__()
        self.body, self.config, self.perceptual = body, config, perceptual
        self.register_buffer("mean", torch.as_tensor(mean))
        self.register_buffer("std", torch.as_tensor(std))

    def denormalise(self, out: torch.Tensor) -> torch.Tensor:
        """Network output -> pose vectors (contact logits become probabilities)."""
        poses = out * self.std + self.mean
        return torch.cat([poses[..., :-2], torch.sigmoid(out[..., -2:])], dim=-1)

    def forward(self, out: torch.Tensor, target_norm: torch.Tensor, words=None):
        c, body = self.config, self.body
        pred, real = self.denormalise(out), target_norm * self.std + self.mean
        pm, proot, _ = body.split(pred)
        rm, rroot, rcont = body.split(real)
        terms = {"rot": geodesic(pm, rm).mean()}
        _, ppos = body.local_positions(pm, proot)
        _, rpos = body.local_positions(rm, rroot)
        terms["pos"] = (ppos - rpos).norm(dim=-1).mean()
        terms["root"] = F.mse_loss(out[..., -6:-2], target_norm[..., -6:-2])
        terms["contact"] = F.binary_cross_entropy_with_logits(out[..., -2:], rcont) + self._skating(ppos, proot, rcont)
        terms["head"] = self._hands_in_head(ppos, rpos)
        total = c.w_rot * terms["rot"] + c.w_pos * terms["pos"] + c.w_root * terms["root"] + \
            c.w_contact * terms["contact"] + c.w_head * terms["head"]
        if c.w_kinetic > 0:
            terms["kinetic"] = self._kinetic(body.world_positions(pm, proot)[1], body.world_positions(rm, rroot)[1])
            total = total + c.w_kinetic * terms["kinetic"]
        if self.perceptual is not None and words is not None and c.w_percept > 0:
            terms["percept"] = self.perceptual(pred, words)
            total = total + c.w_percept * terms["percept"]
        return total, terms

    def _hands_in_head(self, pos: torch.Tensor, real: torch.Tensor) -> torch.Tensor:
        """Mean depth (m) by which generated hands come nearer the head than allowed.

        Allowed is ``HEAD_RADIUS_M`` or, where the real hand is nearer, the real distance:
        the penalty never fights the data.
        """
        if self.body.head < 0 or not self.body.wrists:
            return pos.new_zeros(())
        w, h = self.body.wrists, self.body.head
        d_pred = (pos[..., w, :] - pos[..., h:h + 1, :]).norm(dim=-1)
        d_real = (real[..., w, :] - real[..., h:h + 1, :]).norm(dim=-1)
        return F.relu(d_real.clamp(max=self.HEAD_RADIUS_M) - d_pred).mean()

    def _kinetic(self, pos: torch.Tensor, real: torch.Tensor) -> torch.Tensor:
        """Squared log-ratio of each joint's kinetic statistics over a sequence, generated to real.

        Per sequence and joint: mean horizontal and vertical squared speed and mean
        acceleration magnitude (the kinetic features of FID_k). Frame-wise losses let
        a generator unsure of the timing regress to the mean, a damped motion; these
        statistics ask for the real motion's energy without fixing when it happens.
        """
        def stats(p):
            v = torch.diff(p, dim=1) * self.body.fps
            a = torch.diff(p, n=2, dim=1) * self.body.fps ** 2
            return torch.stack([(v[..., 0] ** 2 + v[..., 2] ** 2).mean(1), (v[..., 1] ** 2).mean(1),
                                a.norm(dim=-1).mean(1)], dim=-1)          # (B, J, 3)

        floor = pos.new_tensor(self.KINETIC_FLOOR)
        return (torch.log(stats(pos) + floor) - torch.log(stats(real) + floor)).pow(2).mean()

    def _skating(self, pos: torch.Tensor, root: torch.Tensor, contacts: torch.Tensor) -> torch.Tensor:
        """Horizontal foot speed (m/s) of the generated motion where the real foot is planted."""
        feet = pos[..., self.body.ankles, :]                   # (B, T, 2, 3) in each frame's heading frame
        dt = 1.0 / self.body.fps
        turn = yaw_matrix(root[..., 1:, 2] * dt).unsqueeze(-3)   # frame t's heading in frame t-1's
        step = torch.stack([root[..., 1:, 1], torch.zeros_like(root[..., 1:, 0]), root[..., 1:, 0]], -1) * dt
        moved = step.unsqueeze(-2) + (turn @ feet[..., 1:, :, :].unsqueeze(-1)).squeeze(-1) - feet[..., :-1, :, :]
        speed = moved[..., [0, 2]].norm(dim=-1) / dt
        planted = contacts[..., 1:, :] * contacts[..., :-1, :]
        return (speed * planted).sum() / planted.sum().clamp(min=1.0)
