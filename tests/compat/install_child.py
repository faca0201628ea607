"""Child process of tests/test_extension_install.py (not a test module itself).

    python -S install_child.py EXTENSION_ZIP

Runs with Blender's user directories pointed at a temporary directory (set by the parent
before bpy is imported) and with only bpy + numpy on sys.path (``-S`` plus PYTHONPATH), the
way Blender itself ships: scipy and embreex can then only come from the extension's wheels.
Installs the zip into the "user_default" repository, enables it, exercises it, uninstalls it,
and prints one JSON line ``RESULT {...}`` with what it observed.
"""

import json
import os
import sys

import bpy

zip_path = sys.argv[1]
result = {"blender": bpy.app.version_string, "python": "%d.%d" % sys.version_info[:2]}

repos = bpy.context.preferences.extensions.repos
repo = next(r for r in repos if r.module == "user_default")
result["repo_directory"] = repo.directory

ret = bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True)
result["install_return"] = sorted(ret)

module_name = "bl_ext.user_default.relight"
result["module_loaded"] = module_name in sys.modules
result["addon_enabled"] = module_name in bpy.context.preferences.addons
mod = sys.modules.get(module_name)
result["module_file"] = getattr(mod, "__file__", None)
ui = sys.modules.get(module_name + ".blender.ui")
result["ui_package_seen"] = getattr(ui, "ADDON_PACKAGE", None)

addon = bpy.context.preferences.addons.get(module_name)
if addon is not None and addon.preferences is not None:
    prefs = addon.preferences
    result["prefs_idname"] = type(prefs).bl_idname
    result["prefs"] = {"sidebar_tab": prefs.sidebar_tab, "threads": prefs.threads}
    prefs.threads = 3
    result["prefs_threads_after_set"] = prefs.threads

# The bundled wheels: where they were installed and whether they import and compute.
try:
    import numpy as np
    import scipy
    import scipy.linalg
    import embreex
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    result["numpy"] = np.__version__
    result["scipy"] = scipy.__version__
    result["scipy_file"] = scipy.__file__
    result["embreex_file"] = embreex.__file__
    # scipy: a 2x2 system with a known solution x = (1, 2).
    result["scipy_solve"] = scipy.linalg.solve(np.array([[2.0, 1.0], [1.0, 3.0]]),
                                               np.array([4.0, 7.0])).tolist()
    # embreex: a ray along -z from z=1 hits the triangle in the z=0 plane at distance 1;
    # a ray beside it misses (-1).
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=np.float32))
    origins = np.array([[0.2, 0.2, 1.0], [2.0, 2.0, 1.0]], dtype=np.float32)
    dirs = np.array([[0, 0, -1], [0, 0, -1]], dtype=np.float32)
    res = scene.run(origins, dirs, output=1)
    result["embree_prim_ids"] = np.asarray(res["primID"]).tolist()
    result["embree_tfar"] = np.asarray(res["tfar"]).tolist()
    del scene, res  # release the Embree scene before its wheel is uninstalled
except Exception as ex:  # reported to the parent, which fails with this message
    result["wheel_error"] = "%s: %s" % (type(ex).__name__, ex)

ret = bpy.ops.extensions.package_uninstall(repo_directory=repo.directory, pkg_id="relight")
result["uninstall_return"] = sorted(ret)
result["addon_enabled_after_uninstall"] = module_name in bpy.context.preferences.addons
result["package_dir_exists_after_uninstall"] = os.path.exists(os.path.join(repo.directory, "relight"))

print("RESULT " + json.dumps(result), flush=True)
