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
