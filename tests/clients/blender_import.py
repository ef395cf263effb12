"""Import a BVH file with Blender's own importer and report what Blender made of it.

Run by tests/test_bvh_clients.py as

    blender -b --factory-startup --python tests/clients/blender_import.py -- FILE EXPECTED_FRAMES OUTJSON [FRAMES]

FRAMES is a comma-separated list of BVH frame indices (0-based) at which to report the
world-space head position of every bone. The JSON holds the bone names, the action's
frame range, the number of BVH frames Blender imported, those positions (Blender's
Z-up world, metres with global_scale=1) and any error text. The script always writes
the JSON, even when the import fails, so the test can show Blender's error.
"""

import builtins
import json
import sys
import traceback

_real_open = builtins.open


def _open_without_U(file, mode="r", *args, **kwargs):
    # Debian's Blender 3.4 importer opens files with mode 'rU', which Python 3.11 rejects.
    if isinstance(mode, str) and "U" in mode:
        mode = mode.replace("U", "") or "r"
    return _real_open(file, mode, *args, **kwargs)


builtins.open = _open_without_U


def main(argv):
    path, expected_frames, out_json = argv[0], int(argv[1]), argv[2]
    sample = [int(f) for f in argv[3].split(",")] if len(argv) > 3 and argv[3] else []
    report = {"file": path, "expected_frames": expected_frames, "errors": [], "bones": [],
              "frame_range": None, "imported_frames": None, "head_positions": {}}
    try:
        import bpy

        result = bpy.ops.import_anim.bvh(
            filepath=path, axis_forward="-Z", axis_up="Y", global_scale=1.0, frame_start=1,
            use_fps_scale=False, update_scene_fps=False, update_scene_duration=True, rotate_mode="NATIVE")
        if "FINISHED" not in result:
            report["errors"].append(f"import_anim.bvh returned {sorted(result)}")
        armatures = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
        if len(armatures) != 1:
            raise RuntimeError(f"expected one armature after import, found {len(armatures)}")
        arm = armatures[0]
        action = arm.animation_data.action
        start, end = action.frame_range
        report["bones"] = [b.name for b in arm.data.bones]
        report["frame_range"] = [start, end]
        report["imported_frames"] = int(round(end - start)) + 1
        scene = bpy.context.scene
        for f in sample:
            scene.frame_set(1 + f)  # BVH frame f is Blender frame frame_start + f
            report["head_positions"][str(f)] = {
                pb.name: list(arm.matrix_world @ pb.head) for pb in arm.pose.bones}
    except Exception:  # report everything: the test shows it
        report["errors"].append(traceback.format_exc())
    with _real_open(out_json, "w") as fh:
        json.dump(report, fh)


main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
