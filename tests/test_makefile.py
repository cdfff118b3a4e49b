"""The Makefile passes a path with a space as one argument (issue 55, case 8: ``make retarget INPUT="a b"`` broke on the
space): ``make -n`` prints each command, read here as a shell would split it."""

import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# (target, the make variables given, an option and the one argument it must receive)
CASES = [
    ("retarget", {"INPUT": "my takes/a b.bvh"}, "--input", "my takes/a b.bvh"),
    ("physicalize", {"TEACHER": "base+residual:my runs/r.pt"}, "--teacher", "base+residual:my runs/r.pt"),
    ("import", {"INPUT": "a b", "OBJECT_MESH": "my box.obj"}, "--object-mesh", "my box.obj"),
    ("import", {"INPUT": "a b"}, "--input", "a b"),
    ("train-residual", {"CKPT": "my ckpts/r.pt"}, "--out", "my ckpts/r.pt"),
    ("train-bc", {"RUN": "my run"}, "--run", "runs/my run"),
    ("distill", {"DISTILL_TEACHER": "my runs/p.pt"}, "--teacher", "my runs/p.pt"),
    ("eval", {"POLICY": "my runs/p.pt"}, "--policy", "my runs/p.pt"),
    ("export", {"POLICY": "my runs/p.pt"}, "--policy", "my runs/p.pt"),
]


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
@pytest.mark.parametrize("target, variables, option, value", CASES, ids=[f"{c[0]} {c[2]}" for c in CASES])
def test_a_path_with_a_space_is_one_argument(target, variables, option, value):
    given = [f"{k}={v}" for k, v in variables.items()]
    # -o: the venv counts as installed (make -n still runs recipe lines holding $(MAKE), the install's among them)
    out = subprocess.run(["make", "-n", "-o", ".venv/.installed", target, *given], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout  # fmt: skip
    (argv,) = [a for a in map(shlex.split, out.replace("\\\n", " ").splitlines()) if option in a]
    assert argv[argv.index(option) + 1] == value, argv
