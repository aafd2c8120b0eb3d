# Run inside Blender (blender -b --factory-startup --python-exit-code 1 --python blender_import.py -- MESH OUT.json): import a mesh
# file as a user would (File > Import: Blender's own OBJ or glTF importer) and write what Blender made of it:
# triangles, UV layers and their coordinates, materials and their base-colour textures.
import json
import sys

import numpy

numpy.bool = bool  # Blender 3.4's glTF importer still uses numpy.bool, which numpy 1.24 dropped

import bpy  # noqa: E402

path, out = sys.argv[sys.argv.index("--") + 1:][:2]
bpy.ops.object.select_all(action="SELECT")
bpy.ops.object.delete()
if path.endswith(".obj"):
    bpy.ops.wm.obj_import(filepath=path)
else:
    bpy.ops.import_scene.gltf(filepath=path)
facts = {"objects": []}
for obj in bpy.context.scene.objects:
    if obj.type != "MESH":
        continue
    mesh = obj.data
    uv = mesh.uv_layers.active
    entry = {"name": obj.name, "polygons": len(mesh.polygons), "triangles": sum(len(p.vertices) - 2 for p in mesh.polygons),
             "vertices": len(mesh.vertices), "uv_layers": len(mesh.uv_layers), "materials": []}
    if uv:
        coords = [tuple(d.uv) for d in uv.data]
        entry["uv_count"] = len(coords)
        entry["uv_mean"] = [sum(c[0] for c in coords) / len(coords), sum(c[1] for c in coords) / len(coords)]
        # Some polygons' corners, each with its world position (the OBJ importer turns the object, the glTF importer
        # the data) and texture coordinate: enough to compare against the file.
        entry["uv_samples"] = [[list(obj.matrix_world @ mesh.vertices[mesh.loops[i].vertex_index].co), list(uv.data[i].uv)] for k in range(0, len(mesh.polygons), 97) for i in mesh.polygons[k].loop_indices]
    for slot in obj.material_slots:
        m = slot.material
        if m is None:
            continue
        image = None
        if m.use_nodes:
            for node in m.node_tree.nodes:
                if node.type == "TEX_IMAGE" and node.image is not None:
                    image = node.image
        entry["materials"].append({"name": m.name, "image": image.filepath if image else None,
                                   "image_size": list(image.size) if image else None,
                                   "image_has_data": bool(image and image.has_data)})
    facts["objects"].append(entry)
with open(out, "w") as f:
    json.dump(facts, f)
