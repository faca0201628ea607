# The real-GUI test, the compatibility runs and the sample scenes (included from the Makefile).
#
# `make test-gui`: the extension zip installed into Debian trixie's Blender 4.3 (a chroot built
#   once into /var/cache/relight-gui/trixie by tools/gui_chroot.sh; needs root and Debian's
#   mirror), driven with real clicks under Xvfb by tests/gui/driver.py, plus the README's
#   headless usage in that Blender binary. Screenshots: out/gui/; docs/img/gui_*.png after a pass.
#   About 5 min on 2 cores once the chroot exists (building it: about 1 min and 1.4 GB).
# `make test-compat`: only tests/test_compat.py (Blender 4.2 LTS, 4.5 LTS, 5.3 as bpy modules);
#   `make test` runs it too.
# `make samples`: rewrite sample_blends/*.blend with Blender 4.2 LTS, so that 4.2+ opens them.

.PHONY: test-gui gui-chroot test-compat samples

test-gui: extension
	$(PY) tools/gui_test.py

gui-chroot:
	tools/gui_chroot.sh ensure

test-compat: setup
	$(PY) -m pytest -q -rs tests/test_compat.py

samples: setup
	$(PY) tests/compat/envs.py --create bpy42
	.venv-bpy42/bin/python sample_blends/generate.py
