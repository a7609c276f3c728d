"""Imports glTF assets into Blender (run by .ci/blender-check.sh, inside `blender -b`).

    blender -b --factory-startup --python .ci/blender-check.py -- FILE:VERTICES:TRIANGLES ...

For each file: a fresh scene, Blender's own glTF importer, then checks that the import raised
nothing, that it made one mesh object with the exported vertex and triangle counts, and that the
mesh's material is a Principled BSDF whose base colour comes from an image texture, with a
normal-map node where the asset has a normal texture. Exits 1 on the first failure.
"""

import sys

import bpy
import numpy

# Debian 12 ships Blender 3.4, whose glTF importer still uses `numpy.bool`, with numpy 1.24,
# which removed it: restore the alias (it was `bool`) so the importer runs.
if "bool" not in numpy.__dict__:
    numpy.bool = bool


def check(path, vertices, triangles, normal_map):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.import_scene.gltf(filepath=path)
    if "FINISHED" not in result:
        raise SystemExit(f"{path}: the importer returned {result}")
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    if len(meshes) != 1:
        raise SystemExit(f"{path}: {len(meshes)} mesh objects, expected 1")
    mesh = meshes[0].data
    mesh.calc_loop_triangles()
    got = (len(mesh.vertices), len(mesh.loop_triangles))
    if got != (vertices, triangles):
        raise SystemExit(f"{path}: {got[0]} vertices, {got[1]} triangles, expected {vertices}, {triangles}")
    if not mesh.materials or mesh.materials[0] is None or not mesh.materials[0].use_nodes:
        raise SystemExit(f"{path}: no node material")
    nodes = mesh.materials[0].node_tree.nodes
    bsdf = [n for n in nodes if n.type == "BSDF_PRINCIPLED"]
    if len(bsdf) != 1:
        raise SystemExit(f"{path}: {len(bsdf)} Principled BSDF nodes, expected 1")
    base = bsdf[0].inputs["Base Color"]
    if not base.is_linked or base.links[0].from_node.type not in ("TEX_IMAGE", "SEPARATE_COLOR", "MIX_RGB", "MIX"):
        raise SystemExit(f"{path}: the base colour does not come from a texture")
    has_normal = any(n.type == "NORMAL_MAP" for n in nodes)
    if has_normal != normal_map:
        raise SystemExit(f"{path}: normal-map node {'missing' if normal_map else 'unexpected'}")
    images = sorted(n.image.name for n in nodes if n.type == "TEX_IMAGE" and n.image)
    print(f"blender-check: {path.rsplit('/', 1)[-1]}: ok: {got[0]} vertices, {got[1]} triangles, "
          f"Principled BSDF, textures {images}, normal map {'yes' if has_normal else 'no'}")


args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
print(f"blender-check: Blender {bpy.app.version_string}")
for arg in args:
    path, vertices, triangles, normal_map = arg.rsplit(":", 3)
    check(path, int(vertices), int(triangles), normal_map == "1")
print(f"blender-check: {len(args)} assets imported")
