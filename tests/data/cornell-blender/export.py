# Writes cornell.glb from cornell.obj with Blender (Debian's `blender` package), the "glTF written by
# another tool" of tests/scene_gltf.rs:
#   blender --background --factory-startup --python tests/data/cornell-blender/export.py
# Faces are one-sided in our OBJ reader, so the materials get backface culling (glTF doubleSided false).
import bpy, os

here = os.path.dirname(os.path.abspath(__file__))
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=os.path.join(here, "cornell.obj"))
for material in bpy.data.materials:
    material.use_backface_culling = True
bpy.ops.export_scene.gltf(
    filepath=os.path.join(here, "cornell.glb"),
    export_format="GLB",
    export_apply=True,
    export_yup=True,
)
print("radiosity export.py: wrote", os.path.join(here, "cornell.glb"), "with Blender", bpy.app.version_string)
