"""Retargeting: a dance moved from the skeleton it was captured on onto the user's character.

It sits between the engines and the exporters (DESIGN.md): ``humanoid`` finds the humanoid
bones in any rig by name and hierarchy, ``rigs`` holds the built-in rigs, ``character``
loads a character (a built-in, a BVH, a glTF/GLB or VRM file), ``solve`` moves the motion.
"""
