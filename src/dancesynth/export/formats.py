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


def output_character(spec=None, bone_map=None, suffix: str = ".bvh"):
    """The character a dance in ``suffix``'s format is written on: a ``Character`` (``spec``: a built-in
    name or a file; default the mannequin), or ``None`` for ``"source"`` (the skeleton the dance was
    made on). Checked before any work, a missing Blender for .fbx too."""
    from ..retarget import SOURCE
    from ..retarget.character import DEFAULT_CHARACTER, load_character

    if suffix == ".fbx":
        from .fbx import find_blender

        find_blender()
    spec = spec or DEFAULT_CHARACTER
    if str(spec) == SOURCE:
        if bone_map is not None:
            raise InputError("--bone-map names the bones of your own --character; it does not apply to 'source'")
        if suffix == ".vrma":
            raise InputError("a .vrma is made on a humanoid rig: leave out --character source")
        return None
    return load_character(spec, bone_map=bone_map)


def write_dance(output: Path, clip, character, *, song: Path | None = None, progress=None) -> None:
    """Write ``clip`` (on ``character``'s skeleton) to ``output`` in its extension's format: whole or
    not at all. A video needs the ``song`` for its sound track; ``progress(done, total)`` follows
    its frames."""
    output = Path(output)
    suffix = check_format(output)
    if suffix == ".mp4":
        from .video import render_video

        render_video(clip, song, output, character=character, progress=progress)
        return
    if suffix == ".bvh":  # block by block: a long dance's text is never whole in memory
        from ..io.bvh_writer import write_bvh

        write_bvh(output, clip if character is None else character.in_own_units(clip))
        return
    from ..io.files import atomic_output

    data = encode_dance(suffix, clip, character)
    with atomic_output(output, "wb") as fh:
        fh.write(data)


def encode_dance(suffix: str, clip, character) -> bytes:
    """``clip`` (on ``character``'s skeleton) as the bytes of a ``suffix`` file (not ``.mp4``)."""
    if suffix == ".bvh":
        from ..io.bvh import format_bvh

        return format_bvh(clip if character is None else character.in_own_units(clip)).encode("utf-8")
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
