# Two entry points: `make repro` (the whole pipeline on params.yaml) and `make test`.
# Both create .venv first if it is missing or older than pyproject.toml / requirements.lock.
SHELL := /bin/bash
# One OpenBLAS kernel on every x86-64 CPU, so runs agree across machines (skt_lib/__init__.py
# sets it too; here it also covers tools that load numpy before skt_lib)
export OPENBLAS_CORETYPE ?= Haswell
# ... on one thread per process: the stages run a process per core (skt_lib/__init__.py too)
export OPENBLAS_NUM_THREADS ?= 1
# numpy's and torch's own SIMD loops held at AVX2 on every x86-64 CPU (skt_lib.SIMD_PINS: an
# AVX-512 CPU's loops round sin, arccos and sums otherwise, and planned other SKTs)
ifeq ($(shell uname -m),x86_64)
export NPY_DISABLE_CPU_FEATURES ?= X86_V4 AVX512_ICL AVX512_SPR
export ATEN_CPU_CAPABILITY ?= avx2
endif
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
UV_VERSION := $(shell sed -n 's/^uv==//p' requirements.lock)

.PHONY: env lock repro paper test browser-tools bench review seeds val-sim camera mutation train-diagnostics clean-env

env: $(STAMP)

$(STAMP): pyproject.toml requirements.lock
	@# open3d dlopens libusb-1.0.so.0 (Debian package libusb-1.0-0).
	@if ! ldconfig -p | grep -q 'libusb-1.0.so.0'; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian package libusb-1.0-0 (needed by open3d)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	  else \
	    echo "ImportError: libusb-1.0.so.0 — open3d needs the Debian package libusb-1.0-0:" \
	         "run 'sudo apt-get install libusb-1.0-0' and retry" >&2; exit 1; \
	  fi; \
	fi
	@[ -x $(BIN)/python ] || $(PYTHON) -m venv $(VENV)
	@# torch first, pinned, by pip (it reads the machine's pip config, e.g. PIP_FIND_LINKS):
	@# the CPU wheel; unpinned it would pull CUDA packages.
	$(BIN)/pip install -q torch==2.13.0
	@# every other package at the version requirements.lock pins: no resolution, no drift.
	@# uv installs them (about 4x faster than pip here, caches empty); pip does it
	@# where uv cannot reach the package index. Bytecode compiled now, as pip does: with
	@# PYTHONDONTWRITEBYTECODE set, every process would compile its imports from source.
	$(BIN)/pip install -q uv==$(UV_VERSION)
	$(BIN)/uv pip install -q --compile-bytecode --python $(BIN)/python --no-deps \
	  -r requirements.lock \
	  || $(BIN)/pip install -q --no-deps -r requirements.lock
	$(BIN)/pip install -q --no-deps -e .
	$(BIN)/pip check
	@touch $(STAMP)

lock:
	@# re-resolve pyproject.toml's pins (with the dev extras) in a scratch venv and write
	@# every installed version to requirements.lock
	rm -rf .lock-venv && $(PYTHON) -m venv .lock-venv
	.lock-venv/bin/pip install -q --upgrade pip
	.lock-venv/bin/pip install -q torch==2.13.0
	.lock-venv/bin/pip install -q -e '.[dev]'
	{ echo "# Every transitive dependency, pinned (torch is installed first, on its own: see Makefile)."; \
	  echo "# Regenerate with \`make lock\` after changing pyproject.toml; \`make env\` installs exactly this."; \
	  .lock-venv/bin/pip freeze --exclude-editable | grep -v '^torch=='; } > requirements.lock
	rm -rf .lock-venv

repro: $(STAMP)
	@# stages run `python -m stages.<name>`: put the venv first on PATH.
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/dvc repro
	@# Table I and the other run figures of README.md and docs/ from the new reports
	$(BIN)/python -m tools.docs_results

# the suite on every core (pytest-xdist), at most four: each worker holds a tiny pipeline's
# data, and some tests start two stage workers of their own; whole files per worker, so a
# module's fixtures are built once
TEST_WORKERS ?= $(shell n=$$(nproc); echo $$(( n < 4 ? n : 4 )))
test: $(STAMP) browser-tools
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

browser-tools:
	@# the Rerun web-viewer tests (tests/test_review.py) screenshot recordings in headless
	@# Chromium and read their labels with tesseract: Debian's packages, installed as root
	@if [ ! -x /usr/bin/chromium ] || ! command -v tesseract >/dev/null; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages chromium and tesseract-ocr (for the viewer tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium tesseract-ocr >/dev/null; \
	  else \
	    echo "the viewer tests will skip: run 'sudo apt-get install chromium tesseract-ocr'" >&2; \
	  fi; \
	fi

SEEDS ?= 3
paper: $(STAMP)
	@# the paper preset (params.paper.yaml over params.yaml) end to end in its own workspace,
	@# paper/ (a clone of HEAD with its own dvc.lock and data/), then SEEDS training seeds in
	@# all for the learned methods; reports into reports/paper/. Resumable: run it again.
	@# Hours on 2 cores (docs/presets.md). Overrides: make paper ARGS='-S compute.n_workers=4'
	$(BIN)/python -m tools.paper --seeds $(SEEDS) $(ARGS)


bench: $(STAMP)
	@# speed figures into reports/bench/bench.json; needs the artifacts of `make repro`
	$(BIN)/python -m stages.bench
	$(BIN)/python -m tools.docs_results

review: $(STAMP)
	@# data/review/review.rrd (representative items of every stage, one tab each) and
	@# reports/<stage>/rerun.png (each recording in Rerun's web viewer, headless Chromium);
	@# needs the artifacts of `make repro`. Installs Debian's chromium when missing (as root).
	@if [ ! -x /usr/bin/chromium ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian package chromium (for screenshots)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else \
	    echo "make review needs /usr/bin/chromium: run 'sudo apt-get install chromium' and retry" >&2; exit 2; \
	  fi; \
	fi
	$(BIN)/python tools/review.py

mutation: $(STAMP)
	@# mutmut on the modules the tests must guard, one at a time, each with its fast unit
	@# tests; summary in reports/tests/mutation.{json,md}. Minutes per module; not in .ci/run.
	@# One module: make mutation MODULES=skt_lib/geometry/skt.py
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python tools/mutation.py $(MODULES)

seeds: $(STAMP)
	@# the learned methods retrained with two more training seeds on the committed data and
	@# evaluated on the same trials (reports/seeds/seed_runs.json), then sim_eval rerun to
	@# merge them into Table I (reports/sim_eval: seeds.<method>.success_mean …), and the default
	@# predictor against vatmart_mod over the seeds (reports/seeds/compare.json); needs an
	@# up-to-date `make repro` (57 min on 2 cores at 9c25640)
	@$(BIN)/dvc status --quiet train train_baselines || { echo "make seeds: the models are not up to date (dvc status train train_baselines): run make repro first" >&2; exit 2; }
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/python -m tools.seed_sweep
	PATH="$(CURDIR)/$(BIN):$$PATH" $(BIN)/dvc repro sim_eval
	$(BIN)/python -m tools.seed_compare
	$(BIN)/python -m tools.docs_results

val-sim: $(STAMP)
	@# the learned methods hang the training objects on the validation supports in
	@# simulation (decisions on hang rates without the test set): data/val_sim/val_sim.json;
	@# needs the artifacts of `make repro`. Other methods or models: ARGS='--methods sctdn
	@# template_only --model sctdn=DIR'. Every proposal of a proposing method, with pick rules
	@# scored on the same trials: python -m tools.val_every (docs/cli.md)
	$(BIN)/python -m tools.val_sim $(ARGS)

camera: $(STAMP)
	@# skt predict --camera on depth-camera views of the test supports (the wall in view, the
	@# sensor model at severities 0-4): support-frame errors against the true camera pose, and
	@# every learned row of Table I hung in simulation from the estimated and the true frame,
	@# each against its own clean success (the default predictor over make seeds' seeds when
	@# current), into reports/camera/; needs the artifacts of `make repro`
	$(BIN)/python -m tools.camera_eval

train-diagnostics: $(STAMP)
	@# short seeded SCTDN runs (overfit one batch, learning curve, contact term, train vs
	@# val) into reports/train/diagnostics.{json,md}, and how far the templates lie from the
	@# labels (reports/train/template_reach.*), and where SCTDN's SKT lets the training objects
	@# hit a Very Hard hook (reports/train/sctdn_sweeps.*); needs the artifacts of `make repro`
	$(BIN)/python tools/train_diagnostics.py
	$(BIN)/python tools/template_reach.py
	$(BIN)/python -m tools.sctdn_sweeps

clean-env:
	rm -rf $(VENV)
