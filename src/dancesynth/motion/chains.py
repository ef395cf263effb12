"""Read a robot-style skeleton as a humanoid: joint chains collapsed into one joint per bone.

Some captures come on skeletons made of one-axis joints -- a robot's hip is a pitch, a roll
and a yaw joint one below the other (the Unitree G1 of ``g1_moves_ccby``), it may have no
neck or head joint, and its joints are named for their axis (``left_hip_pitch_link``). A
*chain map* (TOML, ``[chains]``) says which joints make each humanoid bone::

    [chains]
    hips = ["pelvis"]
    leftUpperLeg = ["left_hip_pitch_link", "left_hip_roll_link", "left_hip_yaw_link"]
    neck = { joints = ["torso_link_end"], at = [0.0, -0.13, 0.0] }

``collapse`` turns a clip into one on a humanoid skeleton with one ball joint per bone, named
with VRM's bone names (``hips``, ``leftUpperLeg``, ...), which every other part of dancesynth
reads. A bone turns as the last joint of its chain turns in the world. Where its joint sits:
- by default, fitted: the point that moves least relative to both the parent bone and the
  bone over the clip (a least-squares joint centre, as used to find hip centres in gait labs),
  nearest the chain's first joint where the motion leaves it free (a hinge's axis);
- ``at = [x, y, z]`` (metres, in the rest pose, from the chain's last joint): a point carried
  by the chain -- for bones the rig lacks (a head and neck that follow the torso, toes at the
  front of a flat robot sole).
``fit_errors`` in the result's meta says, per bone, how far (m, RMS) the collapsed joints are
from where the original skeleton puts them.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..kinematics import fk
from ..types import MotionClip, Skeleton

# The humanoid tree the collapsed skeleton takes, parents first: bone -> parent candidates (first present wins).
_TRUNK = ("upperChest", "chest", "spine", "hips")
TREE = {"hips": (), "spine": ("hips",), "chest": ("spine", "hips"), "upperChest": ("chest", "spine", "hips"),
        "neck": _TRUNK, "head": ("neck",) + _TRUNK}
for _s in ("left", "right"):
    TREE.update({_s + "UpperLeg": ("hips",), _s + "LowerLeg": (_s + "UpperLeg",), _s + "Foot": (_s + "LowerLeg",),
                 _s + "Toes": (_s + "Foot",)})
for _s in ("left", "right"):
    TREE.update({_s + "Shoulder": _TRUNK, _s + "UpperArm": (_s + "Shoulder",) + _TRUNK,
                 _s + "LowerArm": (_s + "UpperArm",), _s + "Hand": (_s + "LowerArm",)})
MAX_FIT_FRAMES = 4000      # frames the joint-centre fit looks at (evenly spread)
MAX_CHAIN_MAP_BYTES = 1 << 20


def read_chain_map(path) -> dict[str, dict]:
    """The ``[chains]`` table of a TOML chain map: bone -> {"joints": [...], "at": None | [x, y, z]}."""
    import tomllib

    from ..io.files import read_user_file

    data = read_user_file(path, limit=MAX_CHAIN_MAP_BYTES, what=f"chain map {path}")
    try:
        table = tomllib.loads(data.decode("utf-8")).get("chains")
    except (UnicodeDecodeError, RecursionError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"chain map {path} is not a valid TOML file ({str(exc).splitlines()[0][:120]})") from None
    return parse_chain_map(table, what=f"chain map {path}")


def parse_chain_map(table, *, what: str = "chain map") -> dict[str, dict]:
    if not isinstance(table, dict) or "hips" not in table:
        raise InputError(f'{what} needs a [chains] table with at least hips, e.g. hips = ["pelvis"]')
    out = {}
    for bone, spec in table.items():
        if bone not in TREE:
            raise InputError(f"{what}: unknown bone {bone!r}; use {', '.join(TREE)}")
        if isinstance(spec, list):
            spec = {"joints": spec}
        joints, at = (spec.get("joints"), spec.get("at")) if isinstance(spec, dict) else (None, None)
        if not (isinstance(joints, list) and joints and all(isinstance(j, str) for j in joints)):
            raise InputError(f"{what}: {bone} must list its joints, e.g. {bone} = [\"joint_a\", \"joint_b\"]")
        if at is not None and not (isinstance(at, list) and len(at) == 3 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) < 100 for x in at)):
            raise InputError(f"{what}: {bone}.at must be three numbers in metres, e.g. at = [0.0, 0.1, 0.0]")
        out[bone] = {"joints": joints, "at": None if at is None else np.asarray(at, dtype=np.float64)}
    return out


def _parent_bone(bone: str, present) -> str | None:
    return next((p for p in TREE[bone] if p in present), None)


def collapse(clip: MotionClip, chains: dict[str, dict], *, what: str = "the clip") -> MotionClip:
    """``clip`` on a humanoid skeleton: one joint per bone of ``chains`` (``parse_chain_map``)."""
    sk = clip.skeleton
    bones = [b for b in TREE if b in chains]      # TREE lists parents first
    for b in bones:
        for j in chains[b]["joints"]:
            if j not in sk.names:
                raise InputError(f"{what}: chain map bone {b} names joint {j!r}, which the skeleton lacks")
        if b != "hips" and _parent_bone(b, chains) is None:
            raise InputError(f"{what}: chain map has {b} but none of {', '.join(TREE[b])} to hang it from")
    if chains["hips"]["joints"][-1] != sk.names[0]:
        raise InputError(f"{what}: the chain map's hips must end at the root joint {sk.names[0]!r}")
    g_rot, g_pos = fk(clip.local_rot, clip.root_pos, sk.offsets, sk.parents, clip.local_pos)
    _, rest_pos = fk(np.tile(rot.IDENTITY, (sk.n_joints, 1))[None], np.zeros((1, 3)), sk.offsets, sk.parents)
    rest_pos = rest_pos[0]
    last = {b: sk.index(chains[b]["joints"][-1]) for b in bones}
    first = {b: sk.index(chains[b]["joints"][0]) for b in bones}
    # Every bone's pivot, as a fixed point of its own frame (the chain's last joint): ``own[b]``.
    own, errors = {"hips": np.zeros(3)}, {"hips": 0.0}
    for b in bones[1:]:
        p = last[_parent_bone(b, chains)]
        if chains[b]["at"] is not None:
            own[b] = chains[b]["at"]
        else:
            own[b] = _joint_centre(g_rot[:, p], g_pos[:, p], g_rot[:, last[b]], g_pos[:, last[b]],
                                   prior_parent=rest_pos[first[b]] - rest_pos[p],
                                   prior_own=rest_pos[first[b]] - rest_pos[last[b]])
    rest = {b: rest_pos[last[b]] + own[b] for b in bones}   # rest rotations are the identity in a BVH
    index = {b: i for i, b in enumerate(bones)}
    parents = np.array([-1] + [index[_parent_bone(b, chains)] for b in bones[1:]])
    offsets = np.array([np.zeros(3)] + [rest[b] - rest[_parent_bone(b, chains)] for b in bones[1:]])
    end_sites = {}
    for b in bones:
        if b in parents:   # not a leaf
            continue
        j = last[b]
        if j in sk.end_sites and chains[b]["at"] is None:
            end_sites[index[b]] = rest_pos[j] + sk.end_sites[j] - rest[b]
        else:   # a point the rig lacks, or a chain ending in a joint: continue along the bone
            end_sites[index[b]] = offsets[index[b]] * 0.5 if np.linalg.norm(offsets[index[b]]) > 0 else np.array(
                [0.0, 0.05, 0.0])
    if "head" in index:
        end_sites[index["head"]] = np.array([0.0, 0.1, 0.0])
    channels = tuple((("Xposition", "Yposition", "Zposition") if i == 0 else ()) + ("Zrotation", "Xrotation",
                                                                                   "Yrotation")
                     for i in range(len(bones)))
    skeleton = Skeleton(tuple(bones), parents, offsets, channels, end_sites)
    world = g_rot[:, [last[b] for b in bones]]
    local = world.copy()
    local[:, 1:] = rot.mul(rot.inv(world[:, parents[1:]]), world[:, 1:])
    out = MotionClip(skeleton, clip.fps, g_pos[:, last["hips"]], local, contacts=clip.contacts, meta=dict(clip.meta))
    _, c_pos = fk(out.local_rot, out.root_pos, offsets, parents)
    for b in bones[1:]:
        if chains[b]["at"] is None:
            true = g_pos[:, last[b]] + rot.apply(g_rot[:, last[b]], own[b])
            errors[b] = float(np.sqrt(np.mean(np.sum((c_pos[:, index[b]] - true) ** 2, axis=-1))))
    out.meta["fit_errors"] = errors
    return out


def _joint_centre(r_parent, p_parent, r_own, p_own, *, prior_parent, prior_own, weight: float = 1e-4) -> np.ndarray:
    """The joint centre as a fixed point of the child's frame: a and b minimising
    |p_parent + R_parent a - (p_own + R_own b)|^2 over frames, plus a small pull towards the priors
    (decides the directions the motion leaves free, such as along a hinge's axis)."""
    n = len(p_parent)
    pick = np.linspace(0, n - 1, min(n, MAX_FIT_FRAMES)).round().astype(int)
    ra, rb = _matrices(r_parent[pick]), _matrices(r_own[pick])
    a = np.concatenate([ra, -rb], axis=2).reshape(-1, 6)
    y = (p_own[pick] - p_parent[pick]).reshape(-1)
    scale = np.sqrt(weight * len(pick))
    a = np.vstack([a, scale * np.eye(6)])
    y = np.concatenate([y, scale * np.concatenate([prior_parent, prior_own])])
    x = np.linalg.lstsq(a, y, rcond=None)[0]
    return x[3:]


def _matrices(q) -> np.ndarray:
    """(N, 3, 3) rotation matrices of quaternions (x, y, z, w)."""
    return np.stack([rot.apply(q, e) for e in np.eye(3)], axis=-1)
