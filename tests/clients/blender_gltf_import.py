"""Blender: import a .glb with its own glTF importer and report every node's world position.

    blender -b --factory-startup --python blender_gltf_import.py -- DANCE.glb FPS REPORT.json F1,F2,...

The importer turns glTF's Y-up into Blender's Z-up and seconds into frames at the scene's rate,
so with the scene at the dance's rate, Blender frame f is the dance's frame f.
"""

import json
import sys

import bpy

path, fps, report_path, frames = sys.argv[sys.argv.index("--") + 1:]
report = {"errors": []}
try:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = int(round(float(fps)))
    bpy.ops.import_scene.gltf(filepath=path)
    objects = {o.name: o for o in bpy.context.scene.objects}
    report["objects"] = sorted(objects)
    report["types"] = sorted({o.type for o in objects.values()})
    report["actions"] = len(bpy.data.actions)
    report["positions"] = {}
    for f in map(int, frames.split(",")):
        bpy.context.scene.frame_set(f)
        report["positions"][str(f)] = {n: list(o.matrix_world.translation) for n, o in objects.items()}
except Exception as exc:  # the report says what went wrong; the test shows it
    report["errors"].append(f"{type(exc).__name__}: {exc}")
with open(report_path, "w") as fh:
    json.dump(report, fh)
