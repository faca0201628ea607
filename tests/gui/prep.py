"""Prepares the chroot's Blender for tests/gui/driver.py (not a pytest module):

    blender -b --factory-startup --python prep.py -- EXTENSION_ZIP

Installs the zip as Edit > Preferences > Get Extensions > Install from Disk does
(``extensions.package_install_files``, enabled on install), turns the splash screen off and
saves the user preferences, so the GUI session starts with the add-on enabled like an artist's.
Prints ``GUI-PREP ok`` when the add-on is enabled.
"""
import sys

import bpy

zip_path = sys.argv[sys.argv.index("--") + 1]
prefs = bpy.context.preferences
ret = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
enabled = "bl_ext.user_default.relight" in prefs.addons
prefs.view.show_splash = False
bpy.ops.wm.save_userpref()
print(f"GUI-PREP {'ok' if ret == {'FINISHED'} and enabled else 'failed'} install={sorted(ret)} enabled={enabled}",
      flush=True)
