"""Runs inside Blender (``bpy``), never imported by dancesynth: a dance's ``.glb`` in, an FBX out.

    blender -b --factory-startup --python-exit-code 3 --python blender_fbx.py -- IN.glb OUT.fbx FPS FRAMES NAME

``dancesynth.export.fbx`` runs it. Blender's glTF importer makes an armature (and the
skinned mesh, if any) in Blender's Z-up world; we keep only those, name the armature
``Armature`` (Blender's own name for one, and what a Mixamo character opened in Blender
has) and export with Blender's FBX exporter: one take named NAME with a key on every frame
0..FRAMES-1, each joint's own transform the rest pose, and each bone's axes its glTF
joint's, so the FBX joints turn by exactly our joints' local rotations.

FBX as game engines and Mixamo write it: Y up, the character facing +Z (Blender's -Y),
centimetres with ``UnitScaleFactor`` 1. Left to itself the exporter puts the change of axes
and the factor 100 into the armature node's transform (rotated -90 degrees, scaled 100),
which Unity and Unreal carry into the scene; so we move both into the data first: the
armature and mesh data are transformed into that space and the armature object given the
inverse transform, which the exporter's own then cancels, leaving the node untransformed
and every bone in centimetres, Y up. The pose in Blender never changes.

Errors are printed as one line starting with ``dancesynth-fbx: `` and fail the run.
Our own code, MIT like the rest of dancesynth; it only calls Blender.
"""

import re
import sys

import bpy
from bpy_extras.io_utils import axis_conversion
from mathutils import Matrix

MARK = "dancesynth-fbx: "
CM_PER_M = 100.0
KEEP = {"ARMATURE", "MESH"}


def main(src, dst, fps, frames, name):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = name                  # the exporter names the one take after the scene
    rate = max(1, round(fps))          # Blender's frame rate is an integer over a divisor
    scene.render.fps, scene.render.fps_base = rate, 1.0
    # A key at t seconds lands on frame t * rate. bone_heuristic BLENDER keeps each bone's frame the glTF
    # joint's own (its bone drawn along the joint's +Y): the FBX joints turn exactly as our joints do.
    # import_shading SMOOTH: the default (NORMALS) calls np.bool, gone from the numpy Debian pairs it with;
    # the mesh keeps the glTF's own normals either way.
    bpy.ops.import_scene.gltf(filepath=src, bone_heuristic="BLENDER", guess_original_bind_pose=True,
                              import_shading="SMOOTH")

    for ob in [ob for ob in scene.objects if ob.type not in KEEP]:   # End Site empties
        bpy.data.objects.remove(ob)
    armatures = [ob for ob in scene.objects if ob.type == "ARMATURE"]
    if len(armatures) != 1:
        raise RuntimeError(f"the glTF made {len(armatures)} armatures, expected 1")
    arm = armatures[0]
    arm.name = arm.data.name = "Armature"
    action = arm.animation_data.action if arm.animation_data else None
    if action is None:
        raise RuntimeError("the glTF's animation did not reach the armature")
    action.name = name
    if rate != fps:   # e.g. 29.97: spread the keys to one per frame, then slow the frames down to match
        for fc in action.fcurves:
            for key in fc.keyframe_points:
                for point in (key.co, key.handle_left, key.handle_right):
                    point.x *= fps / rate
        scene.render.fps_base = rate / fps
    scene.frame_start, scene.frame_end = 0, frames - 1

    to_engine = Matrix.Scale(CM_PER_M, 4) @ axis_conversion(to_forward="-Z", to_up="Y").to_4x4()
    _into_engine_space(arm, action, to_engine)
    _rest_before_the_dance(arm)

    result = bpy.ops.export_scene.fbx(
        filepath=dst, use_selection=False, object_types=KEEP,
        axis_forward="-Z", axis_up="Y", apply_unit_scale=True, apply_scale_options="FBX_SCALE_NONE",
        global_scale=1.0, bake_space_transform=False,    # the exporter's own baking is broken for armatures
        add_leaf_bones=False, primary_bone_axis="Y", secondary_bone_axis="X", armature_nodetype="NULL",
        use_armature_deform_only=False, mesh_smooth_type="FACE",   # Unreal warns without smoothing groups
        bake_anim=True, bake_anim_use_all_bones=True, bake_anim_use_nla_strips=False,
        bake_anim_use_all_actions=False, bake_anim_force_startend_keying=True, bake_anim_step=1.0,
        bake_anim_simplify_factor=0.0,   # every frame keyed exactly: the dance as we made it
        embed_textures=False, use_custom_props=False)
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender's FBX exporter returned {sorted(result)}")


def _into_engine_space(arm, action, to_engine):
    """Move each object's world transform, then ``to_engine``, into its data, and give the object the inverse
    of ``to_engine``: the same pose in Blender, and FBX nodes with no transform of their own."""
    scene = bpy.context.scene
    if any(not fc.data_path.startswith("pose.bones") for fc in action.fcurves):
        raise RuntimeError("the glTF animates the node above the skeleton; FBX export supports only its joints")
    into_data = to_engine @ arm.matrix_world       # a model's armature node may turn and scale (cm -> m)
    scale = into_data.to_scale()
    if max(scale) - min(scale) > 1e-6 * max(scale):
        raise RuntimeError("the glTF scales the skeleton unevenly; FBX export needs the same scale on every axis")
    arm.data.transform(into_data)
    # A pose bone's location is in its rest frame, which turned with the data: only the scale is left to apply.
    for fc in action.fcurves:
        if fc.data_path.endswith(".location"):
            for key in fc.keyframe_points:
                for point in (key.co, key.handle_left, key.handle_right):
                    point.y *= scale[0]
    meshes = [(ob, ob.matrix_world.copy()) for ob in scene.objects if ob.type == "MESH"]
    for ob, world in meshes:
        ob.data.transform(to_engine @ world, shape_keys=True)
    arm.matrix_world = to_engine.inverted()
    bpy.context.view_layer.update()
    for ob, _ in meshes:   # a skinned mesh, the armature's child, is there already
        ob.matrix_world = to_engine.inverted()


def _rest_before_the_dance(arm):
    """Key every bone on frame 0 and the rest pose on frame -1, and stand there: the exporter writes each
    node's own transform from the current frame, and the rest (T-)pose is what Unity builds an avatar from."""
    scene = bpy.context.scene
    scene.frame_set(0)
    channels = ("location", "rotation_quaternion", "scale")
    for pb in arm.pose.bones:   # a joint the glTF never turns has no curve, only a pose that must last
        for channel in channels:
            pb.keyframe_insert(channel, frame=0, group=pb.name)
    for pb in arm.pose.bones:
        pb.matrix_basis = Matrix.Identity(4)
        for channel in channels:
            pb.keyframe_insert(channel, frame=-1, group=pb.name)
    scene.frame_set(-1)


def _one_line(exc):
    """An exception as one line. A failed operator's is many (a whole traceback, then where it was
    raised): its last ``SomeError: ...`` line says what happened."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    errors = [ln for ln in lines if re.match(r"[\w.]*(Error|Exception): ", ln)]
    return errors[-1] if errors else f"{type(exc).__name__}: {lines[0] if lines else ''}"


if __name__ == "__main__":
    try:
        src_arg, dst_arg, fps_arg, frames_arg, name_arg = sys.argv[sys.argv.index("--") + 1:]
        main(src_arg, dst_arg, float(fps_arg), int(frames_arg), name_arg)
    except Exception as exc:   # Blender prints the traceback; we add the one line dancesynth shows
        line = _one_line(exc)
        if "No module named 'numpy'" in line:   # Debian's Blender runs its glTF importer on the system's numpy
            line += " (Blender's glTF importer needs it: apt-get install python3-numpy)"
        print(MARK + line, file=sys.stderr)   # a script in Blender: stderr is how dancesynth.export.fbx hears it
        raise
