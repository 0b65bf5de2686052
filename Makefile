# The two quick-start commands: `make demo` and `make test`. Each creates or updates the local
# virtualenv (.venv) itself, so a fresh machine needs only Python 3.11+.

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: demo test bench models clean soak fuzz

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

test: $(VENV)/.dev-installed
	$(PY) -m pytest -q $(ARGS)

bench: $(VENV)/.dev-installed
	$(PY) benchmarks/model_bench.py
	$(PY) benchmarks/host_bench.py --zenoh

# Retrain the shipped models and rewrite models/MODEL_CARD.md (~45 min on 2 cores; needs dev.json).
models: $(VENV)/.dev-installed
	scripts/train_models.sh

# Not in CI. The demo under load with a hostile phase, RSS sampled each minute (default 30 min,
# 10 cameras x 10 people; e.g. make soak ARGS="--minutes 5 --cameras 6 --people 5").
soak: $(VENV)/.dev-installed
	$(PY) benchmarks/soak.py $(ARGS)

# Not in CI. 100,000 fuzzed Observation and PoseArray payloads through the decoders.
fuzz: $(VENV)/.dev-installed
	$(PY) benchmarks/fuzz.py $(ARGS)

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
