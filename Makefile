# LessMimic toolkit. Every target installs what it needs on first use into .venv.
#   make retarget physicalize features [INPUT=<file or folder>] [NAME=<dataset name>]
#   make corpus [SEEDS=0-24] [CORPUS=corpus] [JOBS=2]   (the same three stages on a synthetic training corpus)
#   (a rerun with the same input and options does nothing: each stage checks the fingerprint in its report.json)
#   make test
#   make bench
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
CLI    := $(VENV)/bin/lessmimic
NAME   ?= default
INPUT  ?=
STAGE_ARGS = --name $(NAME) $(if $(INPUT),--input "$(INPUT)") $(if $(OVERWRITE),--overwrite)
# Geometry augmentation (retarget/augment.py): SCALES=0.6,0.8,1,1.2,1.4 retargets every clip once per object scale
# (1: the clip itself; sx:sy:sz per axis), SHAPES=box,cylinder also as a circular cylinder (primitive boxes only).
SCALES ?=
SHAPES ?= box
AUGMENT_ARGS = $(if $(SCALES),--augment-scales $(SCALES) --augment-shapes $(SHAPES))
JOBS ?= 1
EXECUTOR ?= local
RUN_ARGS = -j $(JOBS) --executor $(EXECUTOR)

export HF_HUB_OFFLINE := 1
export TOKENIZERS_PARALLELISM := false

.PHONY: install lint format retarget import physicalize train-residual features corpus subset train-bc train-aip eval test test-fast bench bench-retarget bench-physicalize bench-physicalize-real bench-train bench-train-mjlab bench-features bench-export bench-vision bench-vision-mjlab bench-export-motion export export-motion distill clean-venv

install: $(VENV)/.installed

# uv creates .venv and installs into it: the uv on PATH, else the pinned one pip-installed into build/uv/ by whatever
# python3 the machine has (any version). Where that fails too (Ubuntu without python3-venv) it says how to get uv.
UV_VERSION := 0.13.9
UV_TOOL    := build/uv
UV         ?= $(or $(shell command -v uv 2>/dev/null),$(UV_TOOL)/bin/uv)
# The venv's interpreter: $(PYTHON) where it is on PATH, else "3.11": uv takes any Python 3.11 it finds on the machine,
# else downloads its own managed 3.11 (so a machine whose system Python is 3.10 or 3.12 needs no 3.11 installed).
VENV_PYTHON = $(or $(shell command -v $(PYTHON) 2>/dev/null),3.11)

$(UV_TOOL)/bin/uv:
	@echo "uv not on PATH: installing uv==$(UV_VERSION) into $(UV_TOOL)/ with python3 -m venv + pip"
	@rm -rf $(UV_TOOL); python3 -m venv $(UV_TOOL) && $(UV_TOOL)/bin/pip install --quiet --disable-pip-version-check "uv==$(UV_VERSION)" \
		|| { rm -rf $(UV_TOOL); echo "error: no uv, and python3 could not install it; get uv with: curl -LsSf https://astral.sh/uv/install.sh | sh  (then rerun make in a new shell)"; exit 1; }

# constraints.txt pins every transitive package (regenerate: uv pip compile pyproject.toml --extra dev -o constraints.txt).
# uv resolves and installs the pinned set in about a minute with a warm cache (pip: ~12 min).
$(VENV)/.installed: pyproject.toml constraints.txt
	@command -v $(UV) >/dev/null || $(MAKE) --no-print-directory $(UV)
	@test -x $(PY) || command -v $(PYTHON) >/dev/null || echo "$(PYTHON) not on PATH: uv takes another Python 3.11 on this machine, else downloads its own"
	test -x $(PY) || { rm -rf $(VENV) && $(UV) venv --python $(VENV_PYTHON) $(VENV); }
	$(UV) pip install --python $(PY) -c constraints.txt -e ".[dev]"
	touch $@

# RETARGET_ARGS: the readers' and scaling's options, e.g. "--fps 30 --units cm --height 1.62" (lessmimic retarget -h)
RETARGET_ARGS ?=
retarget: install
	$(CLI) retarget $(STAGE_ARGS) $(RUN_ARGS) $(AUGMENT_ARGS) $(RETARGET_ARGS)

# Bring your own G1 motion (BeyondMimic .npz, GMR .pkl, HDMI folders) as the retargeted stage: make import physicalize features INPUT=...
OBJECT_MESH ?=
OBJECT_MASS ?=
import: install
	$(CLI) import --name $(NAME) $(if $(INPUT),--input "$(INPUT)") $(if $(OVERWRITE),--overwrite) $(RUN_ARGS) \
		$(if $(OBJECT_MESH),--object-mesh "$(OBJECT_MESH)") $(if $(OBJECT_MASS),--object-mass $(OBJECT_MASS))

TEACHER ?= base
PROFILE ?= mjlab
# SEARCH_BUDGET: children per second of motion of the search with the QP in the loop where the teacher falls
# (physicalize/search/; 0: no search; the default is SearchConfig's)
SEARCH_BUDGET ?=
physicalize: install
	$(CLI) physicalize $(STAGE_ARGS) $(RUN_ARGS) --teacher "$(TEACHER)" --profile $(PROFILE) $(if $(KEEP_INVALID),--keep-invalid) \
		$(if $(SEARCH_BUDGET),--search-budget $(SEARCH_BUDGET))

# Smoke scale (CPU, ~1-2 min): a residual on one retargeted clip; then `make physicalize TEACHER=base+residual:$(CKPT)`.
EPISODE ?= 0
ITERATIONS ?= 20
ENVS ?= 8
SEED ?= 0
CKPT ?= datasets/$(NAME)/residual_ep$(EPISODE).pt
train-residual: install
	$(CLI) physicalize-residual --name $(NAME) --episode $(EPISODE) --iterations $(ITERATIONS) --envs $(ENVS) --seed $(SEED) --out "$(CKPT)"

features: install
	$(CLI) features --name $(NAME) $(if $(OVERWRITE),--overwrite) $(RUN_ARGS)

# A synthetic training corpus: retarget, physicalize, features on INPUT=synthetic:$(SEEDS) into datasets/$(CORPUS)/.
# SEEDS: a range A-B, a seed, or a comma list, optionally :Task,Task (e.g. 0-24:PickUp,Push); every seed gives the
# four synthetic tasks with the objects moved a few cm. CPU cost (SEEDS=0-24 = 100 clips, JOBS=2 on 2 cores, ~9 min):
# retarget ~2 min, physicalize ~7 min (91 clips valid), features ~20 s. Resumable like every stage (rerun the same
# command after an interruption); another SEEDS over an existing corpus needs OVERWRITE=1. PROFILE=lessmimic_demo
# physicalizes under the released demo's stiffer gains (81 clips valid; the policy trained on it acts for those gains).
# With SCALES (and SHAPES) every clip comes in those object variants, each physicalized and validated on its own;
# the physicalize report's "yield" counts valid / rejected / failed per task and variant: `make corpus CORPUS=aug
# SEEDS=0-9 SCALES=0.4,0.6,0.8,1,1.2,1.4,1.6 SHAPES=box,cylinder JOBS=2`.
# ABLATION=-Syn builds the -Syn ablation's twin corpus datasets/$(CORPUS)-syn/: the same retargeted clips, not
# physicalized (physicalize teacher `kinematic`: the motion as it is, its physics measured, every clip kept; ~3 min).
CORPUS ?= corpus
SEEDS ?= 0-24
ABLATION ?=
SYN = $(filter -Syn,$(ABLATION))
CORPUS_ARGS = --name $(CORPUS)$(if $(SYN),-syn) $(if $(OVERWRITE),--overwrite) $(RUN_ARGS)
corpus: install
	$(CLI) retarget $(CORPUS_ARGS) --input synthetic:$(SEEDS) $(AUGMENT_ARGS)
	$(CLI) physicalize $(CORPUS_ARGS) --teacher $(if $(SYN),kinematic,$(TEACHER)) --profile $(PROFILE) $(if $(KEEP_INVALID),--keep-invalid)
	$(CLI) features $(CORPUS_ARGS)

# The held-out protocol (issue #43): a training corpus of some variants of an augmented corpus, the others never
# trained on: `make subset CORPUS=aug SUBSET=aug-train VARIANTS=x0.6,x0.8,x1,x1.2,x1.4`, then `make train-bc
# CORPUS=aug-train RUN=aug` and `make eval CORPUS=aug POLICY=runs/aug/policy.pt EVAL_ARGS="--protocol matched"`.
SUBSET ?= $(CORPUS)-train
VARIANTS ?=
subset: install
	$(CLI) subset --name $(CORPUS) --out $(SUBSET) --variants $(VARIANTS) $(if $(OVERWRITE),--overwrite)

# Train I (paper Sec. III-B): the DF VAE, behaviour cloning on the corpus, DAgger from the QP teacher, into runs/$(RUN)/.
# Laptop scale by default (2 CPU cores, ~58 min on the 100-clip corpus: VAE + BC ~6 min, 26 DAgger iterations ~1.75 min
# each, the last six ~2.7 min with refits twice as long, then policy.pt: the mean of the last three iterations'
# weights; TRAIN_ARGS="--select-episodes 12" chooses the three by validation rollouts instead, ~5 min more:
# train/evaluation/select.py); resumable, and TRAIN_ARGS="--dagger-iterations 40" continues a finished run;
# TRAIN_ARGS for more, e.g.
# TRAIN_ARGS="--bc-steps 200000 --device cuda". `make eval` scores the run's policy and the QP teacher baseline
# (Table 2 cells, 3 evaluation seeds x 16 episodes per cell, each with its 95% interval) into runs/$(RUN)/eval/.
RUN ?= bc
TRAIN_ARGS ?=
# CONTRACT=lessmimic_demo trains on the released web demo's observation (for `make export FORMAT=lessmimic-demo`),
# on a corpus physicalized under its gains: `make corpus CORPUS=demo PROFILE=lessmimic_demo`, then
# `make train-bc CORPUS=demo RUN=demo CONTRACT=lessmimic_demo`.
CONTRACT ?= lessmimic
train-bc: install
	$(CLI) train-bc --name $(CORPUS) --run "runs/$(RUN)" --contract $(CONTRACT) $(if $(ABLATION),--ablation=$(ABLATION)) $(if $(OVERWRITE),--overwrite) $(TRAIN_ARGS)

# Train II (paper Sec. III-C): PPO from runs/$(RUN)/policy.pt with the AIP and AMP style priors, objects scaled per
# axis in 0.4-1.6, into runs/$(RUN)/aip/: 600 iterations x 8 envs x 24 steps = 115k env steps, ~10 min on one core, a
# smoke scale for RL; resumable, and AIP_ARGS="--iterations 1200" continues a finished run. Score it with
# `make eval POLICY=runs/$(RUN)/aip/policy.pt`.
# Table 2's ablations (train/ablation.py): ABLATION=-AIP or -Rand post-trains into runs/$(RUN)/aip-AIP/ or aip-Rand/;
# -Syn and -Trans are their own pre-training runs (`make corpus ABLATION=-Syn`, then `make train-bc ABLATION=-Syn`:
# runs/$(RUN)-Syn/; -Trans: runs/$(RUN)-Trans/, an MLP), post-trained by `make train-aip ABLATION=-Syn` into
# runs/$(RUN)-Syn/aip/; -RL is runs/$(RUN)/policy.pt as it is. Every row is scored on the full corpus by `make eval`.
# BACKEND=mjlab steps the environments on a GPU through mjlab (MuJoCo Warp), 4096 by default (train/envs/mjlab/;
# box and chair objects: the four tasks; meshes stay on the CPU), into runs/$(RUN)/aip-mjlab/; the default, cpu, is native MuJoCo.
AIP_ARGS ?=
BACKEND ?= cpu
train-aip: install
	$(CLI) train-aip --name $(CORPUS) --run "runs/$(RUN)" --backend $(BACKEND) $(if $(ABLATION),--ablation=$(ABLATION)) $(AIP_ARGS)

# Train III (paper Sec. III-D): a vision student distilled from DISTILL_TEACHER (a MoCap-DF policy; default the run's) by
# DAgger on egocentric depth (64 x 40 at the G1's D435 mount) under the physical and the sensor's randomisations, into
# runs/$(RUN)/vision/: 12 iterations x (16 + 8 probe) episodes, refits of 800 x 256 windows, ~1 h on one core;
# resumable. DISTILL_ARGS="--align 1" the latent-alignment ablation, "--randomization off|full" the physical ones.
# Score it beside its teacher: `make eval POLICY=runs/$(RUN)/vision/policy.pt EVAL_ARGS="--scales 1.0 --chains 5"`.
DISTILL_TEACHER ?= runs/$(RUN)/policy.pt
DISTILL_ARGS ?=
distill: install
	$(CLI) distill --name $(CORPUS) --teacher "$(DISTILL_TEACHER)" --run "runs/$(RUN)/vision" $(if $(OVERWRITE),--overwrite) $(DISTILL_ARGS)

# EVAL_ARGS="--chains 5,10" adds the long-horizon chains (Table 3) of the policy; "--episodes 8" more per cell.
# POLICY=runs/$(RUN)/policy.onnx evaluates the exported file through onnxruntime in the same harness.
POLICY ?= runs/$(RUN)/policy.pt
EVAL_ARGS ?=
eval: install
	$(CLI) eval --name $(CORPUS) --policy "$(POLICY)" --teacher $(EVAL_ARGS)

# The policy as ONNX with its metadata (train/export/): runs/$(RUN)/policy.onnx beside POLICY; EXPORT_ARGS="--overwrite".
# FORMAT=lessmimic-demo: the released web demo's three files in runs/$(RUN)/lessmimic_demo/ (a CONTRACT=lessmimic_demo run).
FORMAT ?= onnx
EXPORT_ARGS ?=
export: install
	$(CLI) export --policy "$(POLICY)" --format $(FORMAT) $(EXPORT_ARGS)

# A dataset's G1 motions for other trainers (motion_export/): the valid episodes of datasets/$(NAME)/physicalized/ as
# FORMAT=mjlab-npz (default here: mjlab's tracking task / BeyondMimic), hdmi (motion.npz + meta.json folders), gmr (.pkl)
# or unitree-csv (Unitree's G1 CSV, resampled to 30 Hz), each with a JSON sidecar (gains, physics, object, validity),
# into datasets/$(NAME)/export/$(FORMAT)/; MOTION_ARGS="--episode 3", "--all" (invalid ones too), "--stage retargeted",
# "--out DIR"; OVERWRITE=1 replaces an earlier export.
MOTION_FORMAT = $(if $(filter file,$(origin FORMAT)),mjlab-npz,$(FORMAT))
MOTION_ARGS ?=
export-motion: install
	$(CLI) export-motion --name $(NAME) --format $(MOTION_FORMAT) $(if $(OVERWRITE),--overwrite) $(MOTION_ARGS)

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

# Real mocap: every clip of FOLDERS (default: ../shared/mocap interact, omomo, intermimic), valid / rejected / failed,
# per kind of take and per object; BENCH_ARGS=--sensitivity adds the physics ranges' low and high ends.
FOLDERS ?=
BENCH_ARGS ?=
bench-physicalize-real: install
	$(PY) bench/bench_physicalize_real.py $(FOLDERS) -j $(JOBS) $(BENCH_ARGS)

bench-train: install
	$(PY) bench/bench_train.py --name $(NAME)

# The mjlab backend's speed on a CUDA GPU (bench/bench_train_mjlab.py): physics alone, the environment, and PPO
# plain / + randomisations / + priors at 4096 worlds, from POLICY (a BC + DAgger policy.pt).
bench-train-mjlab: install
	$(PY) bench/bench_train_mjlab.py --name $(CORPUS) --policy "$(POLICY)"

bench-features: install
	$(PY) bench/bench_features.py

# ONNX export beside its torch checkpoint (bench/bench_export.py): export seconds, parity on recorded observations,
# latency of one call; POLICY a trained policy.pt.
bench-export: install
	$(PY) bench/bench_export.py --policy "$(POLICY)" --name $(CORPUS)

# Motion export per format (bench/bench_export_motion.py): file size and frames written per second over the valid
# episodes of datasets/$(CORPUS)/physicalized/.
bench-export-motion: install
	$(PY) bench/bench_export_motion.py --name $(CORPUS)

# The vision stage's speed (bench/bench_vision.py); POLICY (or RUN) a MoCap policy.pt, default runs/adam_seed0/policy.pt.
bench-vision: install
	$(PY) bench/bench_vision.py --name $(CORPUS) $(if $(filter-out file,$(origin POLICY) $(origin RUN)),--policy "$(POLICY)")

# Depth on mjlab, CUDA GPU (bench/bench_vision_mjlab.py): env steps/s at 4096 worlds without and with the depth camera.
bench-vision-mjlab: install
	$(PY) bench/bench_vision_mjlab.py --name $(CORPUS) $(if $(filter-out file,$(origin POLICY) $(origin RUN)),--policy "$(POLICY)") $(BENCH_ARGS)

# The GPU slot's payload (bench/gpu_slot.sh, issue 43 part 6; no venv needed): the wheels the GPU machine's image lacks
# (bench/gpu_slot_wheels.txt) for its Python 3.12 from PyPI, imageio-ffmpeg's binary-free wheel built from its PyPI
# sdist, then `gpu_slot.sh pack`: those wheels, datasets/$(CORPUS)/ (xz) and runs/$(RUN)/policy.pt as one tar in
# pieces of 60 MiB with a sha256 manifest in build/gpu-slot/, and build/gpu-slot/CALLS.txt: the device calls that
# carry them (CORPUS and RUN default to aug-train and aug here).
.PHONY: gpu-slot-wheels
gpu-slot-wheels:
	env -u PIP_FIND_LINKS PIP_CONFIG_FILE=/dev/null python3 -m pip download --quiet --no-deps --only-binary=:all: \
		--python-version 3.12 --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
		--platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --index-url https://pypi.org/simple \
		-d build/gpu-slot/wheels -r bench/gpu_slot_wheels.txt
	env -u PIP_FIND_LINKS PIP_CONFIG_FILE=/dev/null python3 -m pip wheel --quiet --no-deps --no-binary imageio-ffmpeg \
		--index-url https://pypi.org/simple -w build/gpu-slot/wheels imageio-ffmpeg==0.8.1
	bash bench/gpu_slot.sh pack --corpus $(if $(filter file,$(origin CORPUS)),aug-train,$(CORPUS)) \
		--run $(if $(filter file,$(origin RUN)),aug,$(RUN))

clean-venv:
	rm -rf $(VENV)
