"""The file formats a dance is written in, chosen by the output's extension.

``encode_dance`` takes a dance already on its character (``retarget``) and returns the
file's bytes. Writers needing more than the dance (the video needs the song) live elsewhere
(``video``), but their extension is listed here so every command names the same formats.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError

FORMATS = {
    ".bvh": "BVH (skeleton + motion)",
    ".glb": "glTF binary (skinned character + animation, or the dance added to your own model)",
    ".vrma": "VRM Animation, for any VRM avatar",
    ".fbx": "FBX, written by Blender (needs the blender program)",
    ".mp4": "video of the character dancing, with the song",
}


def check_format(path: Path) -> str:
    """``path``'s extension, refused unless a dance can be written in it."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"cannot write {Path(path).name}: a dance is written as "
                         + ", ".join(f"{s} ({d.split(' (')[0].split(',')[0]})" for s, d in FORMATS.items()))
    return suffix


def encode_dance(suffix: str, clip, character) -> bytes:
    """``clip`` (on ``character``'s skeleton) as the bytes of a ``suffix`` file (not ``.mp4``)."""
    if suffix == ".bvh":
        from ..io.bvh import format_bvh

        return format_bvh(clip).encode("utf-8")
    if suffix in (".glb", ".fbx"):
        glb = _glb(clip, character)
        if suffix == ".glb":
            return glb
        from .fbx import fbx_bytes

        return fbx_bytes(glb, fps=clip.fps, name="dance")
    if suffix == ".vrma":
        from .vrm import vrma_bytes

        return vrma_bytes(clip, character.bones)
    raise InputError(f"cannot encode a dance as {suffix}")


def _glb(clip, character) -> bytes:
    if character.source is not None and character.kind != "bvh":   # the user's own model, with our dance
        from .onto_model import onto_model_bytes

        return onto_model_bytes(character, clip)
    from .gltf import glb_bytes

    if character.mesh is None:
        return glb_bytes(clip)
    return glb_bytes(clip, mesh=character.mesh, rest_rot=character.rest_rot, rest_root=character.rest_root)
