#!/usr/bin/env bash
# One GPU slot of mjlab post-training from the augmented policy (issue 43, part 6), resumable across slots.
#
#   here:   make gpu-slot-wheels                      wheels + corpus + starting policy -> build/gpu-slot/ (pieces, manifest)
#           bash bench/gpu_slot.sh plan               build/gpu-slot/CALLS.txt: the device calls, sized (rerun per lease)
#   device: bash bench/gpu_slot.sh stash              one call per piece: check it, keep it outside the repo copy
#           bash bench/gpu_slot.sh run --budget 520   the last call: (a) reassemble + install, (b) resume, (c) train,
#                                                     (d) the checkpoint and logs into $OUT
#   here:   bash bench/gpu_slot.sh restore DIR        DIR: the run tool's files_at; -> runs/<RUN>/aip-mjlab/
#   then:   lessmimic eval --name aug --policy runs/aug/aip-mjlab/policy.pt --teacher --protocol matched --episodes 8
#
# `run --dry-run` prints the phases with their figures and runs nothing; `run` also works on a CPU (--device cpu
# --envs 2 --no-install, with a budget of a few minutes): the same phases at smoke scale.
#
# THE PLAN AND ITS ARITHMETIC (/work/.library/device/README.md; sizes measured here 2026-11-28, no GPU run yet):
# * The device machine's image has Python 3.12 (/opt/torch/.venv) with torch 2.11 (CUDA 13), numpy, scipy, pyarrow,
#   matplotlib, tensorboard, onnx, ...; it reaches no registry. What the mjlab backend imports on top (measured: the
#   distributions a CPU run of `train-aip --backend mjlab` loads, less the image's) is bench/gpu_slot_wheels.txt:
#   32 wheels, 213.9 MiB, warp-lang alone 142 MiB (imageio-ffmpeg's binary-free wheel, built from its sdist: 17 kB
#   instead of 65 MiB). The corpus datasets/aug-train/ is 155 MiB, 117.4 MiB as tar.xz (its parquet is snappy); the
#   starting policy runs/aug/policy.pt 2.1 MiB. Together one uncompressed tar, the bundle: 333.4 MiB.
# * What travels per call (tracked + untracked-not-ignored files + carried paths; the repo's own files ~2.2 MiB) is
#   at most 64 MiB; so the bundle goes in pieces of 60 MiB (`split -b 60M`), one per call: 6 pieces, the last
#   33.4 MiB. A staging call carries one piece and build/gpu-slot/MANIFEST.sha256 and runs `stash`, which checks the
#   piece's sha256 and moves it to $STORE (/var/tmp/lessmimic-gpu-slot, outside the repo copy): it lasts while the
#   machine is held, and a machine goes back 30 s after a call, so the calls go back to back. The last call carries
#   the last piece, the manifest and runs/aug/aip-mjlab/ (the resume checkpoint, 22.6 MiB: post_state.pt 20.5 MiB,
#   policy.pt 2.1 MiB, post_log.jsonl; absent on the first lease): 33.4 + 22.6 + 2.2 = 58.2 MiB, under 64. `plan`
#   recomputes this from the real sizes and prints the exact calls (a staging call more where the last would not fit).
# * Device time, 15 min per session all told: start 1-2 min, 5 staging calls ~20-30 s each (transfer + the gap to the
#   next call): ~10 min are left for the last call, whose command may run 10 min at most. In it: reassembly, checks
#   and the corpus ~10 s (8 s here), pip install of the wheels ~5-30 s (4 s here), then train-aip: ~30 s of imports
#   and reference buffers and ~80 s of first kernel compile (FIELD-NOTES, H200), then PPO at 4096 worlds x 24 steps =
#   98k env steps an iteration, ~2.7 s each (36k env steps/s with the priors and randomisations, H200). With
#   --budget 520: ~430 s of training, ~120 s of it start-up, so ~100-110 iterations, ~10M env steps a slot (the CPU
#   post-training of runs/aug/aip/: 115k).
# * train-aip has no time-based stop, and nothing is added to train/ for one: post_train writes policy.pt and
#   post_state.pt (atomically) after EVERY iteration and resumes after the last one written. So `run` gives
#   --iterations = the resumed iteration + what the remaining time fits (--startup, 150 s assumed for the first
#   start; the seconds per iteration from the carried post_log.jsonl, else --iter-s, 3.0 s; 10% spare), so that the
#   run ends by itself and writes report.json, and wraps it in `timeout` (SIGINT, then SIGKILL) to keep the time to
#   copy back: a stop mid-iteration loses that iteration only (report.json then absent: eval says "unknown" scale).
#   Time left after an early end goes to another round from the checkpoint (kernels cached then, ~60 s start-up).
# * Back through $OUT (at most 8 files, 16 MiB each, 64 MiB together): post_state.pt in pieces of 15 MiB
#   (post_state.pt.part-0, -1), policy.pt, post_log.jsonl, report.json (when the last round ended by itself),
#   slot.log (the whole log's last 15 MiB), RETURN.sha256 (sums of all, and of post_state.pt whole): 7 files, ~24 MB.
#   `restore` checks the sums and puts them into runs/<RUN>/aip-mjlab/ (the files it replaces kept in
#   runs/<RUN>/aip-mjlab.prev/, the log in runs/<RUN>/gpu-slot-logs/), so the next lease carries that folder on.
# * Box and chair objects only: the mjlab backend itself runs only the episodes whose one object is a primitive box or
#   a chair (train/envs/mjlab/env.py runnable_episodes; meshes and several objects are left to the CPU backend, said on
#   stderr); every valid episode of aug-train is one box or chair (no such note in a run on it). The post-training
#   recipe is unchanged: its randomisations still scale the object 0.4-1.6 per axis and draw half the boxes as
#   cylinders, so the held-out geometries of aug-train (0.4x, 1.6x, cylinders) are seen in post-training.
set -euo pipefail

REPO=$(pwd)
SLOT=build/gpu-slot                      # here: wheels/, pieces/, MANIFEST.sha256, CALLS.txt
STORE=${GPU_SLOT_STORE:-/var/tmp/lessmimic-gpu-slot}   # device: pieces/, bundle/, site/ (outside the repo copy)
CALL_LIMIT=$((64 * 1024 * 1024))         # what travels in one call (README: Limits)
OUT_FILE_MIB=15                          # each returned file under the 16 MiB limit

now() { date +%s.%N; }
elapsed() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
phase() { echo; echo "== [$(elapsed "$T0") s] $*"; }
die() { echo "error: $*" >&2; exit 1; }
mib() { awk -v b="$1" 'BEGIN { printf "%.1f MiB", b / 1048576 }'; }
T0=$(now)

usage() {
  sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'
  cat <<'EOF'
options:
  pack:    --corpus NAME (aug-train) --run NAME (aug) --piece-mib N (60)
  run:     --corpus NAME (aug-train) --run NAME (aug) --budget S (520: seconds for the whole command; keep timeout_s
           >= S + 20) --envs N (train-aip's: 4096) --device D (cuda) --iter-s S (seconds per iteration when no
           earlier GPU log says; 3.0) --startup S (seconds train-aip takes to its first iteration: imports,
           buffers, kernel compile; 150; later rounds min(S, 60)) --python PY (python3) --no-install (PY has the
           packages: a CPU smoke test)
           --out DIR ($OUT) --dry-run
  restore: DIR [--run NAME (aug)]
EOF
}

# -- options ---------------------------------------------------------------------------------------------------------
CMD=${1:-}; [[ -n $CMD ]] && shift || { usage; exit 2; }
CORPUS=aug-train RUN=aug PIECE_MIB=60 BUDGET=520 ENVS="" DEVICE=cuda ITER_S_DEFAULT=3.0 STARTUP=150 PY=python3 INSTALL=1
OUTDIR=${OUT:-} DRY=0 ARGS=()
while (($#)); do
  case $1 in
    --corpus) CORPUS=$2; shift 2 ;;
    --run) RUN=$2; shift 2 ;;
    --piece-mib) PIECE_MIB=$2; shift 2 ;;
    --budget) BUDGET=$2; shift 2 ;;
    --envs) ENVS=$2; shift 2 ;;
    --device) DEVICE=$2; shift 2 ;;
    --iter-s) ITER_S_DEFAULT=$2; shift 2 ;;
    --startup) STARTUP=$2; shift 2 ;;
    --python) PY=$2; shift 2 ;;
    --no-install) INSTALL=0; shift ;;
    --out) OUTDIR=$2; shift 2 ;;
    --dry-run) DRY=1; shift ;;
    -h|--help) usage; exit 0 ;;
    -*) die "unknown option $1 (bash bench/gpu_slot.sh --help)" ;;
    *) ARGS+=("$1"); shift ;;
  esac
done
[[ $BUDGET =~ ^[0-9]+$ ]] || die "--budget: whole seconds, got '$BUDGET'"
[[ $PIECE_MIB =~ ^[0-9]+$ && $PIECE_MIB -ge 1 && $PIECE_MIB -le 62 ]] || die "--piece-mib: 1-62, got '$PIECE_MIB'"
[[ -z $ENVS || $ENVS =~ ^[0-9]+$ ]] || die "--envs: a number, got '$ENVS'"
[[ $STARTUP =~ ^[0-9]+$ ]] || die "--startup: whole seconds, got '$STARTUP'"
POST=runs/$RUN/aip-mjlab                 # where train-aip --backend mjlab writes and resumes (lessmimic train-aip)

# -- here: the bundle ------------------------------------------------------------------------------------------------
# The wheels named in bench/gpu_slot_wheels.txt (one file each; a stale other version in the folder is left out) and
# imageio-ffmpeg's; error where one is missing.
listed_wheels() {
  local line name ver f b found
  while read -r line; do
    line=${line%%#*}; line=${line//[[:space:]]/}; [[ -z $line ]] && continue
    name=${line%%==*}; ver=${line#*==}; name=${name//-/_}; found=""
    for f in "$SLOT"/wheels/*.whl; do
      b=${f##*/}; [[ ${b,,} == "${name,,}-${ver}-"*.whl ]] && found=$f
    done
    [[ -n $found ]] || die "no wheel for $line in $SLOT/wheels/: run make gpu-slot-wheels"
    echo "$found"
  done < <(cat bench/gpu_slot_wheels.txt; echo "imageio-ffmpeg==0.8.1")
}

cmd_pack() {
  local data=datasets/$CORPUS policy=runs/$RUN/policy.pt stage=$SLOT/bundle
  [[ -d $data/features && -d $data/physicalized && -d $data/retargeted ]] || die "$data: not a corpus (make corpus / make subset)"
  [[ -f $policy ]] || die "$policy: no BC + DAgger policy (make train-bc CORPUS=$CORPUS RUN=$RUN)"
  phase "pack: wheels, datasets/$CORPUS, $policy -> $SLOT/pieces (${PIECE_MIB} MiB each)"
  rm -rf "$stage" "$SLOT/pieces" "$SLOT/bundle.tar"; mkdir -p "$stage/wheels" "$stage/run" "$SLOT/pieces"
  listed_wheels > "$stage/wheels.txt"   # in this shell: a missing wheel stops the pack
  local w; while read -r w; do ln "$w" "$stage/wheels/" 2>/dev/null || cp "$w" "$stage/wheels/"; done < "$stage/wheels.txt"
  rm "$stage/wheels.txt"
  # the corpus as tar.xz, remade only when a file of it is newer than the last one
  local xzf=$SLOT/corpus-$CORPUS.tar.xz
  if [[ ! -f $xzf ]] || [[ -n $(find "$data" -newer "$xzf" -print -quit) ]]; then
    echo "compressing $data ($(du -sh "$data" | cut -f1)) with xz -6 ..."
    tar --sort=name --owner=0 --group=0 --numeric-owner -cf - "$data" | nice xz -6 -T2 > "$xzf.tmp"
    mv "$xzf.tmp" "$xzf"
  fi
  ln "$xzf" "$stage/corpus.tar.xz" 2>/dev/null || cp "$xzf" "$stage/corpus.tar.xz"
  cp "$policy" "$stage/run/policy.pt"
  [[ -f runs/$RUN/report.json ]] && cp "runs/$RUN/report.json" "$stage/run/report.json"
  printf '{"corpus": "%s", "run": "%s", "policy_sha256": "%s", "wheels": %s}\n' "$CORPUS" "$RUN" \
    "$(sha256sum "$policy" | cut -d' ' -f1)" "$(ls "$stage/wheels" | wc -l)" > "$stage/bundle.json"
  # one deterministic tar (no compression: wheels and xz do not shrink), split, summed
  tar -C "$stage" --sort=name --owner=0 --group=0 --numeric-owner --mtime=@0 -cf "$SLOT/bundle.tar" .
  split -b "${PIECE_MIB}M" -d -a 2 "$SLOT/bundle.tar" "$SLOT/pieces/bundle.part-"
  {
    (cd "$SLOT/pieces" && sha256sum bundle.part-*)
    (cd "$SLOT" && sha256sum bundle.tar)
  } > "$SLOT/MANIFEST.sha256"
  echo "bundle $(mib "$(stat -c %s "$SLOT/bundle.tar")"): $(ls "$stage/wheels" | wc -l) wheels" \
    "$(mib "$(du -cb "$stage"/wheels/*.whl | tail -1 | cut -f1)"), corpus.tar.xz $(mib "$(stat -c %s "$xzf")")," \
    "policy $(mib "$(stat -c %s "$policy")"); pieces: $(ls "$SLOT/pieces" | wc -l)"
  rm -rf "$stage" "$SLOT/bundle.tar"
  cmd_plan
}

# The calls, from the real sizes: a staging call per piece, the last call with the resume folder and the pieces that
# fit beside it. Printed and written to CALLS.txt.
cmd_plan() {
  [[ -f $SLOT/MANIFEST.sha256 ]] || die "no $SLOT/MANIFEST.sha256: run make gpu-slot-wheels"
  local tree resume=0 manifest pieces=() sizes=() p n i
  if git rev-parse --git-dir >/dev/null 2>&1; then   # the files that travel anyway: tracked, untracked not ignored
    tree=$( (git ls-files -z; git ls-files -z -o --exclude-standard) | xargs -0 -r stat -c %s 2>/dev/null \
      | awk '{s += $1} END {print s + 0}') || true
  else
    tree=$((3 * 1024 * 1024)); echo "(not a git checkout: the repo's own files counted as 3 MiB)"
  fi
  manifest=$(stat -c %s "$SLOT/MANIFEST.sha256")
  [[ -d $POST ]] && resume=$(du -sb "$POST" | cut -f1)
  mapfile -t pieces < <(grep -o 'bundle\.part-[0-9]*' "$SLOT/MANIFEST.sha256")
  for p in "${pieces[@]}"; do
    [[ -f $SLOT/pieces/$p ]] || die "$SLOT/pieces/$p missing: run make gpu-slot-wheels"
    sizes+=("$(stat -c %s "$SLOT/pieces/$p")")
  done
  n=${#pieces[@]}
  local room=$((CALL_LIMIT - tree - manifest - resume)) last=$n
  ((room > 0)) || die "the resume folder $POST ($(mib "$resume")) and the tree leave no room in a call"
  while ((last > 0 && sizes[last - 1] <= room)); do room=$((room - sizes[last - 1])); last=$((last - 1)); done
  {
    echo "# $(date -u +%FT%TZ): tree $(mib "$tree"), resume $POST $(mib "$resume"), ${n} pieces;" \
      "$((last + 1)) calls, back to back (a held machine goes back 30 s after a call)"
    echo "# first: the status tool (free): can_start_another must be true; call budget_left_s B."
    for ((i = 0; i < last; i++)); do
      echo "call $((i + 1)) (staging, $(mib $((tree + manifest + sizes[i]))) travels): run(command=\"bash bench/gpu_slot.sh stash\"," \
        "carry=[\"$SLOT/MANIFEST.sha256\", \"$SLOT/pieces/${pieces[i]}\"], timeout_s=120)"
    done
    local carry="\"$SLOT/MANIFEST.sha256\""
    for ((i = last; i < n; i++)); do carry+=", \"$SLOT/pieces/${pieces[i]}\""; done
    carry+=", \"$POST\""
    echo "call $((last + 1)) (last, $(mib $((CALL_LIMIT - room))) travels): run(command=\"bash bench/gpu_slot.sh run" \
      "--budget S\", carry=[$carry], timeout_s=S+20), with S = min(560, B_now - 70), B_now: status's budget_left_s now"
    echo "then: give_back; bash bench/gpu_slot.sh restore <files_at> --run $RUN; the CPU eval (bench/gpu_slot.sh header)"
  } | tee "$SLOT/CALLS.txt"
}

# -- device: staging -------------------------------------------------------------------------------------------------
# Move the carried pieces that match the manifest into $STORE/pieces; a new manifest (a repacked bundle) empties it.
cmd_stash() {
  [[ -f $SLOT/MANIFEST.sha256 ]] || die "carry $SLOT/MANIFEST.sha256 in every call"
  mkdir -p "$STORE/pieces"
  if ! cmp -s "$SLOT/MANIFEST.sha256" "$STORE/MANIFEST.sha256"; then
    rm -rf "$STORE/pieces" "$STORE/bundle" "$STORE/site"; mkdir -p "$STORE/pieces"
    cp "$SLOT/MANIFEST.sha256" "$STORE/MANIFEST.sha256"
  fi
  local p line sum name have=0 want=0 missing=()
  for p in "$SLOT"/pieces/bundle.part-*; do
    [[ -f $p ]] || continue
    name=${p##*/}; line=$(grep " $name\$" "$STORE/MANIFEST.sha256" || true)
    [[ -n $line ]] || die "$name is not in the manifest"
    sum=$(sha256sum "$p" | cut -d' ' -f1)
    [[ $sum == "${line%% *}" ]] || die "$name: sha256 $sum, the manifest says ${line%% *} (a broken transfer: carry it again)"
    mv "$p" "$STORE/pieces/$name"; echo "stashed $name ($(mib "$(stat -c %s "$STORE/pieces/$name")"), sha256 ok)"
  done
  while read -r sum name; do
    [[ $name == bundle.part-* ]] || continue
    want=$((want + 1))
    if [[ -f $STORE/pieces/$name ]]; then have=$((have + 1)); else missing+=("$name"); fi
  done < "$STORE/MANIFEST.sha256"
  echo "pieces in $STORE: $have of $want${missing:+; missing: ${missing[*]}}"
  STASH_COMPLETE=$((have == want))
}

# -- device: the slot ------------------------------------------------------------------------------------------------
# (a) every piece present and summed, the bundle summed, unpacked; the wheels installed with the image's Python;
#     the corpus and the starting policy in place.
phase_install() {
  phase "(a) reassemble the bundle, install the wheels"
  if ((DRY)); then
    echo "would: stash the carried pieces; cat $STORE/pieces/bundle.part-* (sha256 = the manifest's bundle.tar) | tar -x -C $STORE/bundle"
    echo "would: $PY -m pip install --no-index --no-deps --no-compile --target $STORE/site $STORE/bundle/wheels/*.whl"
    echo "would: datasets/$CORPUS/ from corpus.tar.xz; runs/$RUN/policy.pt from the bundle; PYTHONPATH=$REPO:$STORE/site"
    echo "(dry run: counted as 50 s, the expected time of this phase on the device)"
    T0=$(awk -v t="$T0" 'BEGIN { printf "%.3f", t - 50 }')
    return
  fi
  local t=$(now) want got
  cmd_stash
  ((STASH_COMPLETE)) || die "pieces missing (the machine was given back between calls?): carry them again, then run"
  want=$(awk '$2 == "bundle.tar" {print $1}' "$STORE/MANIFEST.sha256")
  if [[ $(cat "$STORE/bundle/.sha256" 2>/dev/null) != "$want" ]]; then
    got=$(cat "$STORE"/pieces/bundle.part-* | sha256sum | cut -d' ' -f1)
    [[ $got == "$want" ]] || die "the reassembled bundle's sha256 is $got, the manifest says $want"
    rm -rf "$STORE/bundle" "$STORE/site"; mkdir -p "$STORE/bundle"
    cat "$STORE"/pieces/bundle.part-* | tar -x -C "$STORE/bundle"
    echo "$want" > "$STORE/bundle/.sha256"
    echo "bundle reassembled and unpacked in $(elapsed "$t") s (sha256 $want)"
  else
    echo "bundle already unpacked here (sha256 $want)"
  fi
  # Not a venv: the image's python3 is itself a venv holding torch, and a venv made from it would not see those
  # packages; a --target folder on PYTHONPATH (the device README's recipe) adds to them, ours first. The project
  # is not pip-installed either (pyproject asks for Python 3.11; an editable install with --target is refused): the
  # repo root on PYTHONPATH and `python -m lessmimic` are what an editable install gives.
  if ((INSTALL)) && [[ ! -f $STORE/site/.installed ]]; then
    t=$(now)
    "$PY" -m pip install --quiet --disable-pip-version-check --no-index --no-deps --no-compile --no-cache-dir \
      --target "$STORE/site" "$STORE"/bundle/wheels/*.whl
    touch "$STORE/site/.installed"
    echo "installed $(ls "$STORE"/bundle/wheels/*.whl | wc -l) wheels into $STORE/site in $(elapsed "$t") s"
  fi
  t=$(now)
  # the corpus and the starting policy from the bundle; a corpus or policy already here that did not come from a
  # bundle (run outside the device) is kept as it is
  local data=datasets/$CORPUS
  if [[ -d $data && ! -f $data/.gpu-slot ]]; then
    echo "$data is here and not from a bundle: kept"
  elif [[ $(cat "$data/.gpu-slot" 2>/dev/null) != "$want" ]]; then
    rm -rf "$data"
    if command -v xz >/dev/null; then tar -xJf "$STORE/bundle/corpus.tar.xz"
    else "$PY" -c 'import sys, tarfile; tarfile.open(sys.argv[1]).extractall(".", filter="data")' "$STORE/bundle/corpus.tar.xz"; fi
    echo "$want" > "$data/.gpu-slot"
  fi
  mkdir -p "runs/$RUN"
  if [[ ! -f runs/$RUN/policy.pt ]]; then
    cp "$STORE/bundle/run/policy.pt" "runs/$RUN/policy.pt"
    [[ -f $STORE/bundle/run/report.json ]] && cp "$STORE/bundle/run/report.json" "runs/$RUN/report.json"
  elif ! cmp -s "$STORE/bundle/run/policy.pt" "runs/$RUN/policy.pt"; then
    echo "warning: runs/$RUN/policy.pt is here and differs from the bundle's: kept (post-training starts from it)"
  fi
  echo "datasets/$CORPUS ($(du -sh "$data" | cut -f1)) and runs/$RUN/policy.pt in place in $(elapsed "$t") s"
}

# The last finished iteration of the carried checkpoint (-1: none) and the median seconds of an iteration of the
# same size in its log (empty: none).
resume_state() {
  "$PY" - "$POST" "${ENVS:-4096}" <<'EOF'
import json, statistics, sys
from pathlib import Path
post, envs = Path(sys.argv[1]), int(sys.argv[2])
it, secs = -1, []
log = post / "post_log.jsonl"
if (post / "post_state.pt").is_file() and log.is_file():
    rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    if rows:
        it = rows[-1]["iteration"]
        per = [r for r in rows if r["env_steps"] == (r["iteration"] + 1) * envs * 24]
        secs = [r["seconds"] for r in per[-50:]]
elif (post / "post_state.pt").is_file():
    import torch
    it = torch.load(post / "post_state.pt", map_location="cpu", weights_only=False)["iteration"]
print(it, f"{statistics.median(secs):.3f}" if secs else "")
EOF
}

phase_resume() {
  phase "(b) resume"
  if [[ -f $POST/post_state.pt ]]; then
    echo "carried checkpoint: $POST (post_state.pt $(mib "$(stat -c %s "$POST/post_state.pt")"), sha256" \
      "$(sha256sum "$POST/post_state.pt" | cut -c1-16)...)"
  else
    echo "no $POST/post_state.pt carried: a fresh post-training run from runs/$RUN/policy.pt"
  fi
}

# (c) train-aip in rounds until the budget's training share is spent: each round's iterations sized to end by itself.
phase_train() {
  phase "(c) train-aip --backend mjlab"
  local site=""; ((INSTALL)) && site=":$STORE/site"
  export PYTHONPATH="$REPO$site${PYTHONPATH:+:$PYTHONPATH}"
  # no rendering in training (MUJOCO_GL=disable: no GL library needed); quiet kernel loads, a progress line per 20 s
  export MUJOCO_GL=disable PYTHONUNBUFFERED=1 HF_HUB_OFFLINE=1 WANDB_MODE=disabled MJLAB_WARP_QUIET=1 TQDM_MININTERVAL=20
  local reserve=45 cold=$STARTUP warm=$((STARTUP < 60 ? STARTUP : 60)) round=0 start iter_s left train_s n iters rc t
  read -r start iter_s < <(resume_state) || true
  start=${start:--1}
  echo "resumes after iteration $start; seconds per iteration: ${iter_s:-$ITER_S_DEFAULT (assumed)}"
  iter_s=${iter_s:-$ITER_S_DEFAULT}
  while :; do
    left=$(awk -v b="$BUDGET" -v e="$(elapsed "$T0")" 'BEGIN { printf "%d", b - e }')
    local startup=$cold; ((round > 0)) && startup=$warm
    train_s=$((left - reserve))
    # 10% spare on the seconds per iteration: a round should end by itself (and write report.json), not by the timeout
    n=$(awk -v s="$train_s" -v u="$startup" -v i="$iter_s" 'BEGIN { n = int((s - u) / (1.1 * i)); print (n < 0 ? 0 : n) }')
    if ((n < 1 || (round > 0 && n < 10))); then
      echo "${left} s left: no room for another round (start-up ~${startup} s, ${iter_s} s an iteration)"; break
    fi
    iters=$((start + 1 + n))
    local cmd=("$PY" -m lessmimic train-aip --name "$CORPUS" --run "runs/$RUN" --backend mjlab --device "$DEVICE"
               --iterations "$iters" ${ENVS:+--envs "$ENVS"})
    echo "round $((round + 1)): ${train_s} s (start-up ~${startup} s + $n iterations x ${iter_s} s): iterations $((start + 1))-$((iters - 1))"
    echo "  timeout -s INT -k 15 $train_s ${cmd[*]}"
    if ((DRY)); then start=$((iters - 1)); round=$((round + 1)); T0=$(awk -v t="$T0" -v s="$train_s" 'BEGIN { printf "%.3f", t - s }'); continue; fi
    t=$(now)
    rm -f "$POST/report.json"   # written only by a run that ends by itself: never a stale one
    set +e
    timeout -s INT -k 15 "$train_s" "${cmd[@]}"
    rc=$?
    set -e
    echo "round $((round + 1)) ended: exit $rc$( ((rc == 124)) && echo ' (timeout: stopped after its last saved iteration)') in $(elapsed "$t") s"
    round=$((round + 1))
    read -r start iter_s < <(resume_state) || true
    start=${start:--1} iter_s=${iter_s:-$ITER_S_DEFAULT}
    ((rc == 0)) || break              # a failure or the timeout: no further round
  done
  TRAIN_ROUNDS=$round
}

# (d) the checkpoint and the logs into $OUT, each file under 16 MiB, at most 8.
phase_return() {
  phase "(d) the checkpoint into ${OUTDIR:-\$OUT}"
  if ((DRY)); then
    echo "would: $POST/post_state.pt in ${OUT_FILE_MIB} MiB pieces, policy.pt, post_log.jsonl, report.json, slot.log, RETURN.sha256"
    return
  fi
  [[ -n $OUTDIR ]] || die "no \$OUT (pass --out DIR here)"
  mkdir -p "$OUTDIR"
  if [[ ! -f $POST/post_state.pt ]]; then echo "no checkpoint was written (see the log above)"; fi
  local f
  if [[ -f $POST/post_state.pt ]]; then
    split -b "${OUT_FILE_MIB}M" -d -a 1 "$POST/post_state.pt" "$OUTDIR/post_state.pt.part-"
    for f in policy.pt post_log.jsonl report.json; do [[ -f $POST/$f ]] && cp "$POST/$f" "$OUTDIR/"; done
  fi
  (cd "$OUTDIR" && sha256sum -- * > RETURN.sha256.tmp 2>/dev/null || true)
  [[ -f $POST/post_state.pt ]] && (cd "$POST" && sha256sum post_state.pt) >> "$OUTDIR/RETURN.sha256.tmp"
  mv "$OUTDIR/RETURN.sha256.tmp" "$OUTDIR/RETURN.sha256"
  if (($(ls "$OUTDIR" | wc -l) > 7)); then   # 8 files come back at most, slot.log the 8th
    rm -f "$OUTDIR/report.json"; echo "warning: too many files for \$OUT: report.json left out"
  fi
  phase "done: $(ls "$OUTDIR" | wc -l) files in ${OUTDIR} (+ slot.log)"
  if [[ -f $POST/post_log.jsonl ]]; then
    tail -n 1 "$POST/post_log.jsonl" | "$PY" -c 'import json,sys; r=json.loads(sys.stdin.read()); print("last row: iteration", r["iteration"], "env_steps", r["env_steps"], "task_reward %.3f" % r["task_reward"], "seconds %.2f" % r["seconds"])' || true
  fi
  echo "TIMINGS (s): ${TIMINGS[*]} total=$(elapsed "$T0")"
  sleep 1   # let tee write the log
  tail -c "$((OUT_FILE_MIB * 1024 * 1024))" "$LOG" > "$OUTDIR/slot.log"
}

cmd_run() {
  LOG=$STORE/slot-$(date -u +%Y%m%dT%H%M%SZ).log
  mkdir -p "$STORE"
  if ((!DRY)); then exec > >(tee -a "$LOG") 2>&1; fi
  echo "gpu slot: corpus $CORPUS, run $RUN, budget $BUDGET s, device $DEVICE, envs ${ENVS:-4096 (train-aip default)}," \
    "python $("$PY" -c 'import sys; print(sys.version.split()[0])') ($PY), store $STORE, out ${OUTDIR:-unset}$( ((DRY)) && echo ', DRY RUN')"
  if ((!DRY)); then command -v nvidia-smi >/dev/null && nvidia-smi -L || echo "no nvidia-smi"; fi
  TIMINGS=()
  local t=$(now)
  phase_install; TIMINGS+=("install=$(elapsed "$t")"); t=$(now)
  phase_resume; TIMINGS+=("resume=$(elapsed "$t")"); t=$(now)
  phase_train; TIMINGS+=("train=$(elapsed "$t")" "rounds=${TRAIN_ROUNDS:-0}"); t=$(now)
  TIMINGS+=("total_before_copy=$(elapsed "$T0")")
  phase_return
}

# -- here: what came back --------------------------------------------------------------------------------------------
cmd_restore() {
  local dir=${ARGS[0]:-} tmp
  [[ -n $dir && -f $dir/RETURN.sha256 ]] || die "restore DIR: DIR must hold RETURN.sha256 (the run tool's files_at)"
  (cd "$dir" && sha256sum --quiet -c --ignore-missing RETURN.sha256) || die "$dir: a returned file does not match its sum"
  ls "$dir"/post_state.pt.part-* >/dev/null 2>&1 || die "$dir: no post_state.pt pieces came back"
  mkdir -p "runs/$RUN"; tmp=$(mktemp -d "runs/$RUN/.restore.XXXXXX")
  cat "$dir"/post_state.pt.part-* > "$tmp/post_state.pt"
  grep ' post_state.pt$' "$dir/RETURN.sha256" | (cd "$tmp" && sha256sum --quiet -c -) \
    || { rm -rf "$tmp"; die "the reassembled post_state.pt does not match its sum"; }
  local f
  for f in policy.pt post_log.jsonl report.json; do [[ -f $dir/$f ]] && cp "$dir/$f" "$tmp/"; done
  chmod u+w "$tmp"/*   # files_at is read-only; the next run appends to post_log.jsonl
  mkdir -p "$POST" "$POST.prev" "runs/$RUN/gpu-slot-logs"
  for f in post_state.pt policy.pt post_log.jsonl report.json; do [[ -f $POST/$f ]] && mv "$POST/$f" "$POST.prev/"; done
  for f in "$tmp"/*; do mv "$f" "$POST/"; done
  rmdir "$tmp"
  [[ -f $dir/slot.log ]] && cp "$dir/slot.log" "runs/$RUN/gpu-slot-logs/slot-$(date -u +%Y%m%dT%H%M%SZ).log"
  echo "restored into $POST (the files it replaced: $POST.prev/):"; ls -la "$POST"
  tail -n 1 "$POST/post_log.jsonl" 2>/dev/null | cut -c1-200 || true
}

case $CMD in
  pack) cmd_pack ;;
  plan) cmd_plan ;;
  stash) cmd_stash ;;
  run) cmd_run ;;
  restore) cmd_restore ;;
  -h|--help|help) usage ;;
  *) die "unknown command $CMD: pack, plan, stash, run, restore" ;;
esac
