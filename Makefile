# Relight: two commands for a newcomer, `make demo` and `make test`.
# Everything the project needs is installed here, into .venv (pinned versions).
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cksum < requirements.txt | cut -d' ' -f1)
OUT    := out

.PHONY: setup demo test bench extension clean

setup: $(STAMP)

$(STAMP): requirements.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	@rm -f $(VENV)/.installed-* && touch $@

# The main job, headless, on a sample scene: a result .blend, a JSON report and a Cycles picture.
demo: setup
	@mkdir -p $(OUT)/demo
	$(PY) -m relight_addon radiosity sample_blends/cornell_box.blend \
	    --report $(OUT)/demo/report.json --out $(OUT)/demo/cornell_radiosity.blend \
	    --render $(OUT)/demo/cornell_radiosity.png
	@echo "demo: wrote $(OUT)/demo/report.json, $(OUT)/demo/cornell_radiosity.blend, $(OUT)/demo/cornell_radiosity.png"

test: setup
	$(PY) -m pytest -q tests

bench: setup
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(OUT) build dist wheels .pytest_cache
include mk/extension.mk
