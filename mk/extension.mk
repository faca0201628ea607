# Blender extension packaging (owned by the packaging helper; included from the Makefile).
# `make extension`: pip-download the wheels listed in blender_manifest.toml into ./wheels
# (git-ignored cache), stage build/extension/, build one zip per platform into dist/ with
# Blender's own extension tool (from the bpy module, no Blender binary), validate each zip.
# `make compat-envs`: the side venvs used by tests/test_compat.py.

.PHONY: extension extension-force compat-envs

extension: setup
	$(PY) tools/build_extension.py

extension-force: setup
	$(PY) tools/build_extension.py --force

compat-envs: setup
	$(PY) tests/compat/envs.py --create all
