"""The built-in rigs: one body, our canonical proportions, in the joint layouts of the common ecosystems.

Every built-in stands in a T-pose on the floor (y = 0), facing +Z with its left hand
towards +X, in metres: glTF's and VRM 1.0's conventions, and the pose CMU, Daz and
Mixamo rigs rest in. ``mannequin`` is the canonical rig: its joints are named with the
VRM 1.0 humanoid bone names, the names every other rig is mapped to. ``mixamo``, ``vrm``
(VRoid's ``J_Bip_*`` names), ``smpl`` (SMPL's 24 joints in their order) and ``cmu`` (the
31-joint CMU BVH layout) put the same body in those layouts, so a dance exported for one
ecosystem opens with the names that ecosystem's tools already know.
"""

from __future__ import annotations

import numpy as np

from ..types import Skeleton

# The canonical body: T-pose joint positions (metres) of each VRM humanoid bone, left side.
# Height 1.74 m to the top of the head; proportions of an adult dancer.
BODY = {
    "hips": (0.0, 0.96, 0.0),
    "spine": (0.0, 1.06, -0.01),
    "chest": (0.0, 1.18, -0.015),
    "upperChest": (0.0, 1.31, -0.02),
    "neck": (0.0, 1.46, -0.025),
    "head": (0.0, 1.55, -0.01),
    "leftShoulder": (0.03, 1.42, -0.02),
    "leftUpperArm": (0.17, 1.42, -0.03),
    "leftLowerArm": (0.445, 1.42, -0.03),
    "leftHand": (0.69, 1.42, -0.03),
    "leftUpperLeg": (0.09, 0.91, 0.0),
    "leftLowerLeg": (0.095, 0.50, 0.01),
    "leftFoot": (0.10, 0.08, -0.02),
    "leftToes": (0.105, 0.015, 0.11),
}
# Where each chain's last bone ends (End Sites), as offsets from its joint.
TIPS = {"head": (0.0, 0.19, 0.01), "leftHand": (0.17, 0.0, 0.0), "leftToes": (0.0, 0.0, 0.07)}


def body_position(bone: str) -> np.ndarray:
    """The canonical T-pose position of a VRM humanoid bone (right side mirrored)."""
    if bone.startswith("right"):
        x, y, z = BODY["left" + bone[5:]]
        return np.array([-x, y, z])
    return np.array(BODY[bone], dtype=np.float64)


def tip_offset(bone: str) -> np.ndarray:
    key = "left" + bone[5:] if bone.startswith("right") else bone
    x, y, z = TIPS[key]
    return np.array([-x if bone.startswith("right") else x, y, z])


_SIDES = ("left", "right")
_CORE = ["hips", "spine", "chest", "upperChest", "neck", "head"]
_LIMBS = ["Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"]
_LIMB_PARENT = {"Shoulder": "upperChest", "UpperArm": "Shoulder", "LowerArm": "UpperArm", "Hand": "LowerArm",
                "UpperLeg": "hips", "LowerLeg": "UpperLeg", "Foot": "LowerLeg", "Toes": "Foot"}


def _humanoid_layout():
    """(joint, parent, bone) rows of the canonical layout: core first, then each side's arm and leg."""
    rows = [(b, _CORE[i - 1] if i else None, b) for i, b in enumerate(_CORE)]
    for side in _SIDES:
        for part in _LIMBS:
            parent = _LIMB_PARENT[part]
            parent = parent if parent in _CORE else side + parent
            rows.append((side + part, parent, side + part))
    return rows


def _renamed(names: dict[str, str]):
    """The canonical layout with joints renamed: ``names`` maps a VRM bone to the rig's joint name."""
    return [(names[j], names[p] if p else None, b) for j, p, b in _humanoid_layout()]


def _sided(table: dict[str, str], left: str, right: str) -> dict[str, str]:
    """Bone -> joint names for ``table`` written once with ``{s}`` standing for the side's spelling."""
    names = {}
    for bone, name in table.items():
        if "{s}" in name:
            names["left" + bone] = name.format(s=left)
            names["right" + bone] = name.format(s=right)
        else:
            names[bone] = name
    return names


_MIXAMO = _sided({"hips": "mixamorig:Hips", "spine": "mixamorig:Spine", "chest": "mixamorig:Spine1",
                  "upperChest": "mixamorig:Spine2", "neck": "mixamorig:Neck", "head": "mixamorig:Head",
                  "Shoulder": "mixamorig:{s}Shoulder", "UpperArm": "mixamorig:{s}Arm",
                  "LowerArm": "mixamorig:{s}ForeArm", "Hand": "mixamorig:{s}Hand",
                  "UpperLeg": "mixamorig:{s}UpLeg", "LowerLeg": "mixamorig:{s}Leg",
                  "Foot": "mixamorig:{s}Foot", "Toes": "mixamorig:{s}ToeBase"}, "Left", "Right")
_VROID = _sided({"hips": "J_Bip_C_Hips", "spine": "J_Bip_C_Spine", "chest": "J_Bip_C_Chest",
                 "upperChest": "J_Bip_C_UpperChest", "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head",
                 "Shoulder": "J_Bip_{s}_Shoulder", "UpperArm": "J_Bip_{s}_UpperArm",
                 "LowerArm": "J_Bip_{s}_LowerArm", "Hand": "J_Bip_{s}_Hand", "UpperLeg": "J_Bip_{s}_UpperLeg",
                 "LowerLeg": "J_Bip_{s}_LowerLeg", "Foot": "J_Bip_{s}_Foot", "Toes": "J_Bip_{s}_ToeBase"},
                "L", "R")

# SMPL's 24 joints in SMPL's own order (parents come first), each with the bone it stands for;
# left_hand / right_hand sit at the hand's tip (SMPL's hand joint is where the fingers start).
_SMPL = [("pelvis", None, "hips"), ("left_hip", "pelvis", "leftUpperLeg"),
         ("right_hip", "pelvis", "rightUpperLeg"), ("spine1", "pelvis", "spine"),
         ("left_knee", "left_hip", "leftLowerLeg"), ("right_knee", "right_hip", "rightLowerLeg"),
         ("spine2", "spine1", "chest"), ("left_ankle", "left_knee", "leftFoot"),
         ("right_ankle", "right_knee", "rightFoot"), ("spine3", "spine2", "upperChest"),
         ("left_foot", "left_ankle", "leftToes"), ("right_foot", "right_ankle", "rightToes"),
         ("neck", "spine3", "neck"), ("left_collar", "spine3", "leftShoulder"),
         ("right_collar", "spine3", "rightShoulder"), ("head", "neck", "head"),
         ("left_shoulder", "left_collar", "leftUpperArm"), ("right_shoulder", "right_collar", "rightUpperArm"),
         ("left_elbow", "left_shoulder", "leftLowerArm"), ("right_elbow", "right_shoulder", "rightLowerArm"),
         ("left_wrist", "left_elbow", "leftHand"), ("right_wrist", "right_elbow", "rightHand"),
         ("left_hand", "left_wrist", "leftHand+tip"), ("right_hand", "right_wrist", "rightHand+tip")]


def _cmu():
    """The 31-joint layout of the CMU BVH conversions: extra hip, neck and finger joints hold no bone."""
    rows = [("Hips", None, "hips")]
    for s, side in (("L", "Left"), ("R", "Right")):
        low = side.lower()
        rows += [(f"{s}HipJoint", "Hips", "hips"), (f"{side}UpLeg", f"{s}HipJoint", f"{low}UpperLeg"),
                 (f"{side}Leg", f"{side}UpLeg", f"{low}LowerLeg"), (f"{side}Foot", f"{side}Leg", f"{low}Foot"),
                 (f"{side}ToeBase", f"{side}Foot", f"{low}Toes")]
    rows += [("LowerBack", "Hips", "spine"), ("Spine", "LowerBack", "chest"), ("Spine1", "Spine", "upperChest"),
             ("Neck", "Spine1", "neck"), ("Neck1", "Neck", "neck+half"), ("Head", "Neck1", "head")]
    for s, side in (("L", "Left"), ("R", "Right")):
        low = side.lower()
        rows += [(f"{side}Shoulder", "Spine1", f"{low}Shoulder"), (f"{side}Arm", f"{side}Shoulder", f"{low}UpperArm"),
                 (f"{side}ForeArm", f"{side}Arm", f"{low}LowerArm"), (f"{side}Hand", f"{side}ForeArm", f"{low}Hand"),
                 (f"{side}FingerBase", f"{side}Hand", f"{low}Hand+half"),
                 (f"{side}HandIndex1", f"{side}FingerBase", f"{low}Hand+tip"),
                 (f"{s}Thumb", f"{side}Hand", f"{low}Hand+thumb")]
    return rows


LAYOUTS = {
    "mannequin": _humanoid_layout(),
    "mixamo": _renamed(_MIXAMO),
    "vrm": _renamed(_VROID),
    "smpl": _SMPL,
    "cmu": _cmu(),
}
DESCRIPTIONS = {
    "mannequin": "our canonical rig, VRM humanoid bone names, with a skinned low-poly dancer mesh",
    "mixamo": "Mixamo joint names (mixamorig:Hips, mixamorig:LeftArm, ...)",
    "vrm": "VRoid / VRM joint names (J_Bip_C_Hips, J_Bip_L_UpperArm, ...)",
    "smpl": "SMPL's 24 joints in SMPL's order (pelvis, left_hip, ..., right_hand)",
    "cmu": "the 31-joint CMU motion-capture BVH layout (Hips, LHipJoint, LeftUpLeg, ...)",
}

ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
JOINT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")


def _where(spec: str) -> np.ndarray:
    """A joint's position from its spec: a bone, or a bone plus a point along its last segment."""
    bone, _, extra = spec.partition("+")
    p = body_position(bone)
    if extra == "tip":
        return p + tip_offset(bone)
    if extra == "half":
        nxt = {"neck": body_position("head")}.get(bone, p + tip_offset(bone) if bone.endswith("Hand") else p)
        return (p + nxt) / 2
    if extra == "thumb":
        return p + np.array([0.03 if bone.startswith("left") else -0.03, -0.01, 0.04])
    return p


def rig_skeleton(name: str) -> tuple[Skeleton, dict[str, int]]:
    """The built-in rig ``name`` as a Skeleton, and its humanoid bone -> joint map."""
    rows = LAYOUTS[name] if name == "smpl" else _depth_first(LAYOUTS[name])   # SMPL keeps SMPL's order
    names = [r[0] for r in rows]
    index = {n: i for i, n in enumerate(names)}
    world = np.array([_where(r[2]) for r in rows])
    parents = np.array([index[p] if p else -1 for _, p, _ in rows])
    offsets = np.where(parents[:, None] >= 0, world - world[np.maximum(parents, 0)], world)
    bones = {}
    for i, (_, _, spec) in enumerate(rows):
        if "+" not in spec and spec not in bones:
            bones[spec] = i
    end_sites = {i: _leaf_tip(spec) for i, (_, _, spec) in enumerate(rows) if not np.any(parents == i)}
    channels = tuple(ROOT_CHANNELS if p < 0 else JOINT_CHANNELS for p in parents)
    skeleton = Skeleton(tuple(names), parents, offsets, channels, end_sites)
    # Finger joints (CMU's LThumb, LeftHandIndex1) are named for their finger: found as in any rig.
    from .humanoid import find_bones

    return skeleton, {**find_bones(skeleton), **bones}


def _depth_first(rows):
    """Rows in the order a BVH file lists its joints, so a rig read back from BVH keeps its order."""
    out = []

    def visit(row):
        out.append(row)
        for child in rows:
            if child[1] == row[0]:
                visit(child)

    visit(rows[0])
    return out


def _leaf_tip(spec: str) -> np.ndarray:
    """A short End Site continuing a leaf joint (a finger, a thumb, a toe) so its last bone has a length."""
    bone = spec.partition("+")[0]
    if bone.replace("right", "left") in TIPS and "+" not in spec:
        return tip_offset(bone)
    side = -1.0 if bone.startswith("right") else 1.0
    return np.array([side * 0.04, 0.0, 0.0]) if "Hand" in bone else np.array([0.0, 0.0, 0.04])
