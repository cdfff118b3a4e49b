# LessMimic toolkit. Every target installs what it needs on first use into .venv.
#   make retarget physicalize features [INPUT=<file or folder>] [NAME=<dataset name>]
#   (a rerun with the same input and options does nothing: each stage checks the fingerprint in its report.json)
#   make test
#   make bench
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
CLI    := $(VENV)/bin/lessmimic
NAME   ?= default
INPUT  ?=
STAGE_ARGS = --name $(NAME) $(if $(INPUT),--input $(INPUT)) $(if $(OVERWRITE),--overwrite)
JOBS ?= 1
EXECUTOR ?= local
RUN_ARGS = -j $(JOBS) --executor $(EXECUTOR)

export HF_HUB_OFFLINE := 1
export TOKENIZERS_PARALLELISM := false

.PHONY: install lint format retarget import physicalize train-residual features test test-fast bench bench-retarget bench-physicalize bench-physicalize-real bench-features clean-venv

install: $(VENV)/.installed

# constraints.txt pins every transitive package (regenerate: uv pip compile pyproject.toml --extra dev -o constraints.txt).
# uv resolves and installs the pinned set in about a minute with a warm cache (pip: ~12 min).
$(VENV)/.installed: pyproject.toml constraints.txt
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) not found (the toolkit needs Python 3.11)"; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check "uv==0.13.9"
	$(VENV)/bin/uv pip install --python $(PY) -c constraints.txt -e ".[dev]"
	touch $@

retarget: install
	$(CLI) retarget $(STAGE_ARGS) $(RUN_ARGS)

# Bring your own G1 motion (BeyondMimic .npz, GMR .pkl, HDMI folders) as the retargeted stage: make import physicalize features INPUT=...
OBJECT_MESH ?=
OBJECT_MASS ?=
import: install
	$(CLI) import --name $(NAME) $(if $(INPUT),--input $(INPUT)) $(if $(OVERWRITE),--overwrite) $(RUN_ARGS) \
		$(if $(OBJECT_MESH),--object-mesh $(OBJECT_MESH)) $(if $(OBJECT_MASS),--object-mass $(OBJECT_MASS))

TEACHER ?= base
physicalize: install
	$(CLI) physicalize $(STAGE_ARGS) $(RUN_ARGS) --teacher $(TEACHER) $(if $(KEEP_INVALID),--keep-invalid)

# Smoke scale (CPU, ~1-2 min): a residual on one retargeted clip; then `make physicalize TEACHER=base+residual:$(CKPT)`.
EPISODE ?= 0
ITERATIONS ?= 20
ENVS ?= 8
SEED ?= 0
CKPT ?= datasets/$(NAME)/residual_ep$(EPISODE).pt
train-residual: install
	$(CLI) physicalize-residual --name $(NAME) --episode $(EPISODE) --iterations $(ITERATIONS) --envs $(ENVS) --seed $(SEED) --out $(CKPT)

features: install
	$(CLI) features --name $(NAME) $(if $(OVERWRITE),--overwrite) $(RUN_ARGS)

# ruff (pinned in the dev extras, configured in pyproject.toml): `make format` rewrites, `make lint` checks.
lint: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: install
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

test: lint
	$(PY) -m pytest -n 2 --dist loadfile -q tests

test-fast: install
	$(PY) -m pytest -n 2 --dist loadfile -q -m "not slow" tests

bench: install
	$(PY) bench/bench_dataset.py

bench-retarget: install
	$(PY) bench/bench_retarget.py

bench-physicalize: install
	$(PY) bench/bench_physicalize.py

# Real mocap: every clip of FOLDERS (default: ../shared/mocap interact, omomo, intermimic), valid / rejected / failed.
FOLDERS ?=
bench-physicalize-real: install
	$(PY) bench/bench_physicalize_real.py $(FOLDERS) -j $(JOBS)

bench-features: install
	$(PY) bench/bench_features.py

clean-venv:
	rm -rf $(VENV)
