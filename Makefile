# Relight: two commands for a newcomer, `make demo` and `make test`.
# Everything the project needs is installed here, into .venv (pinned versions).
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cksum < requirements.txt | cut -d' ' -f1)
OUT    := out

.PHONY: setup demo test test-all bench extension clean

setup: $(STAMP)

$(STAMP): requirements.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	@rm -f $(VENV)/.installed-* && touch $@

# The main job, headless, on a sample scene: the paper's experiment (staircase with painted
# targets) solved and reduced; a result .blend, a JSON report and a Cycles picture.
demo: setup
	@mkdir -p $(OUT)/demo
	$(PY) -m relight_addon solve sample_blends/staircase_targets.blend \
	    --report $(OUT)/demo/report.json --out $(OUT)/demo/staircase_relit.blend \
	    --render $(OUT)/demo/staircase_relit.png
	@echo "demo: wrote $(OUT)/demo/report.json, $(OUT)/demo/staircase_relit.blend, $(OUT)/demo/staircase_relit.png"

# The fast tiers (tests/conftest.py TIERS: not the Cycles closed loops, the other Blenders'
# runs or the slow tests); `make test-all`: every test (.ci/run runs it, then `make test-gui`).
test: setup
	$(PY) -m pytest -q -m "not cycles and not compat and not slow" tests

test-all: setup
	$(PY) -m pytest -q tests

bench: setup
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(OUT) build dist wheels .pytest_cache
include mk/extension.mk
include mk/gui.mk
