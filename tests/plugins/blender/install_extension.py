"""Run inside a fresh ``bpy`` environment (no hdrio): install the built extension zip,
enable it, and run its operators. Prints one JSON line with what happened.

    python -I install_extension.py EXTENSION.zip BRACKET_DIR OUTPUT.exr

Kept out of pytest's process on purpose: the test environment has hdrio installed, and
this must prove the zip brings hdrio and its dependencies itself.
"""

import importlib
import json
import sys
from pathlib import Path

import bpy

archive, brackets, output = sys.argv[1:4]
result = {}
bpy.ops.extensions.package_install_files(filepath=archive, repo="user_default",
                                         enable_on_install=True)
import hdrio  # noqa: E402  (from the extension's wheels, nothing else has it)

result["hdrio_from"] = hdrio.__file__
result["nodes"] = [bpy.types.Node.bl_rna_get_subclass_py(name) is not None for name in
                   ("CompositorNodeHdrioMerge", "CompositorNodeHdrioReinhardGlobal")]
names = sorted(p.name for p in Path(brackets).glob("*.png"))
result["merge"] = sorted(bpy.ops.hdrio.merge_to_exr(
    directory=brackets, files=[{"name": name} for name in names], output=output))
scene = bpy.context.scene
if bpy.app.version >= (5, 0, 0):
    tree = scene.compositing_node_group
else:
    tree = scene.node_tree
node = tree.nodes.new("CompositorNodeHdrioMerge")
node.bracket_count = len(names)
for index, name in enumerate(names):
    image = tree.nodes.new("CompositorNodeImage")
    image.image = bpy.data.images.load(str(Path(brackets) / name))
    tree.links.new(image.outputs["Image"], node.inputs[index])
node.update()
result["exposures"] = node.bracket_exposures()
result["solve"] = sorted(bpy.ops.hdrio.solve_response(tree_name=tree.name,
                                                       node_name=node.name))
result["response"] = node.response_label()
merged = bpy.data.images.load(output)
result["tonemap"] = sorted(bpy.ops.hdrio.tonemap_local(image_name=merged.name))
warmup = importlib.import_module("bl_ext.user_default.hdrio.warmup").WARMUP
result["warmup"] = [warmup.finished, warmup.error]
result["not_shipped_imported"] = [name for name in ("PIL", "imageio") if name in sys.modules]
print("RESULT " + json.dumps(result))
