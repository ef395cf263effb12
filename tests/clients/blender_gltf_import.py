"""Blender: import a .glb with its own glTF importer and report what it made of it.

    blender -b --factory-startup --python blender_gltf_import.py -- DANCE.glb FPS REPORT.json F1,F2,...

The report holds every object's world position at frames F1, F2, ... and, for a skinned
character, each mesh object's vertex groups and its deformed vertices (world space) at those
frames, each armature's bones, and each action's frame range. The importer turns glTF's Y-up
into Blender's Z-up and seconds into frames at the scene's rate, so with the scene at the
dance's rate, Blender frame f is the dance's frame f.
"""

import json
import sys

import bpy
import numpy

# Blender 3.4's glTF importer smooths a mesh that has normals with numpy's ``np.bool``, an alias
# NumPy 1.24 removed (Debian's Blender runs on the system NumPy): put the alias back.
if "bool" not in vars(numpy):
    numpy.bool = bool

path, fps, report_path, frames = sys.argv[sys.argv.index("--") + 1:]
report = {"errors": []}
try:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = int(round(float(fps)))
    bpy.ops.import_scene.gltf(filepath=path)
    objects = {o.name: o for o in bpy.context.scene.objects}
    meshes = [o for o in objects.values() if o.type == "MESH"]
    report["objects"] = sorted(objects)
    report["types"] = sorted({o.type for o in objects.values()})
    report["actions"] = len(bpy.data.actions)
    report["frame_ranges"] = {a.name: list(a.frame_range) for a in bpy.data.actions}
    report["armatures"] = {o.name: [b.name for b in o.data.bones] for o in objects.values() if o.type == "ARMATURE"}
    report["meshes"] = {o.name: {"vertex_groups": [g.name for g in o.vertex_groups], "vertices": len(o.data.vertices),
                                 "polygons": len(o.data.polygons),
                                 "modifiers": [m.type for m in o.modifiers]} for o in meshes}
    report["positions"], report["deformed"] = {}, {}
    for f in map(int, frames.split(",")):
        bpy.context.scene.frame_set(f)
        report["positions"][str(f)] = {n: list(o.matrix_world.translation) for n, o in objects.items()}
        depsgraph = bpy.context.evaluated_depsgraph_get()
        report["deformed"][str(f)] = {}
        for o in meshes:  # the mesh as the armature deforms it at this frame
            evaluated = o.evaluated_get(depsgraph)
            mesh = evaluated.to_mesh()
            report["deformed"][str(f)][o.name] = [list(evaluated.matrix_world @ v.co) for v in mesh.vertices]
            evaluated.to_mesh_clear()
except Exception as exc:  # the report says what went wrong; the test shows it
    report["errors"].append(f"{type(exc).__name__}: {exc}")
with open(report_path, "w") as fh:
    json.dump(report, fh)
