"""Retargeting: a dance moved from the skeleton it was captured on onto the user's character.

It sits between the engines and the exporters (DESIGN.md): ``humanoid`` finds the humanoid
bones in any rig by name and hierarchy, ``rigs`` holds the built-in rigs, ``character``
loads a character (a built-in, a BVH, a glTF/GLB or VRM file), ``solve`` moves the motion.
"""

from __future__ import annotations


SOURCE = "source"   # --character source: keep the skeleton the style was captured on


def on_character(clip, character="mannequin", *, bone_map=None):
    """``(clip on the character, the Character)``; ``character`` is a built-in name, a file, a
    ``Character``, or ``"source"`` for the skeleton the dance was made on (returned unchanged)."""
    from .character import Character, load_character, source_character
    from .solve import retarget

    if isinstance(character, Character):
        return retarget(clip, character), character
    if str(character) == SOURCE:
        return clip, source_character(clip.skeleton)
    target = load_character(character, bone_map=bone_map)
    return retarget(clip, target), target


class SegmentRetargeter:
    """Retargets a stream's segments one by one onto one character, on one floor: the source's
    standing height is measured on the first segment and kept (each segment measured on its own
    would move the floor between segments)."""

    def __init__(self, character):
        self.character = character
        self._bones = None
        self._ground = None

    def __call__(self, clip):
        from .humanoid import find_bones
        from .solve import retarget, source_ground

        if self._bones is None:
            self._bones = find_bones(clip.skeleton, what="the dance's skeleton")
            self._ground = source_ground(clip, self._bones)
        return retarget(clip, self.character, self._bones, source_ground=self._ground)
