"""Blender: read an FBX twice, as raw FBX records and with Blender's FBX importer, and report what is in it.

    blender -b --factory-startup --python blender_fbx_import.py -- DANCE.fbx REPORT.json F1,F2,...

Raw records (Blender's FBX parser, no conversion): the file's axes and unit (GlobalSettings),
its takes with their length in frames, and each model's type and own transform. Imported
(Blender converts to its Z-up world in metres, keys at the file's frame rate, take time 0 at
frame 0): the armature's bones, its action's frame range and keys per curve, and every bone's
head in world space at the frames asked for. The report is written even when reading fails.
"""

import json
import sys
import traceback

import bpy

KTIME_PER_S = 46186158000   # FBX time unit


def raw_records(path):
    """GlobalSettings, takes and models of the file as FBX stores them."""
    from io_scene_fbx import parse_fbx

    root, version = parse_fbx.parse(path)

    def child(elem, name):
        return next(e for e in elem.elems if e.id == name)

    def props(elem):
        """An element's Properties70 as {name: value or [values]}."""
        out = {}
        for p in child(elem, b"Properties70").elems:
            values = [v.decode() if isinstance(v, bytes) else v for v in p.props[4:]]
            out[p.props[0].decode()] = values[0] if len(values) == 1 else values
        return out

    settings = props(child(root, b"GlobalSettings"))
    objects = child(root, b"Objects")
    models, takes = {}, {}
    for e in objects.elems:
        name = e.props[1].split(b"\x00\x01")[0].decode()
        if e.id == b"Model":
            p = props(e)
            models[name] = {"type": e.props[2].decode(),
                            **{k: p.get(k) for k in ("Lcl Translation", "Lcl Rotation", "Lcl Scaling")}}
        elif e.id == b"AnimationStack":
            p = props(e)
            takes[name] = (p.get("LocalStop", 0) - p.get("LocalStart", 0)) / KTIME_PER_S
    return {"version": version, "settings": settings, "models": models, "take_seconds": takes}


def main(path, report_path, frames):
    report = {"errors": []}
    try:
        report["raw"] = raw_records(path)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        # anim_offset 0: the take's time 0 is frame 0, as in our clips.
        bpy.ops.import_scene.fbx(filepath=path, anim_offset=0.0)
        scene = bpy.context.scene
        report["fps"] = scene.render.fps / scene.render.fps_base
        report["objects"] = {ob.name: ob.type for ob in scene.objects}
        arm = next(ob for ob in scene.objects if ob.type == "ARMATURE")
        report["bones"] = [b.name for b in arm.data.bones]
        action = arm.animation_data.action
        report["action"] = action.name
        report["frame_range"] = list(action.frame_range)
        report["keys_per_curve"] = sorted({len(fc.keyframe_points) for fc in action.fcurves})
        report["positions"] = {}
        for f in frames:
            scene.frame_set(f)
            report["positions"][str(f)] = {pb.name: list(arm.matrix_world @ pb.head) for pb in arm.pose.bones}
    except Exception:  # the report says what went wrong; the test shows it
        report["errors"].append(traceback.format_exc())
    with open(report_path, "w") as fh:
        json.dump(report, fh)


path_arg, report_arg, frames_arg = sys.argv[sys.argv.index("--") + 1:]
main(path_arg, report_arg, [int(f) for f in frames_arg.split(",")])
