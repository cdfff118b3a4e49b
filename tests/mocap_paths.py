"""Where the real mocap test files live, and a check for the readers' bad-input errors.

The files sit outside the repository (``../shared/mocap``, never copied in); tests that need
them are marked ``@needs_shared`` and skip cleanly when the folder is absent.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pipeline.errors import InputError

SHARED_MOCAP = Path(__file__).resolve().parents[1].parent / "shared" / "mocap"

needs_shared = pytest.mark.skipif(
    not SHARED_MOCAP.is_dir(),
    reason=f"real mocap test files not found at {SHARED_MOCAP} (a fresh clone has no ../shared)",
)


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


def expect_input_error(
    call, folder: Path, *, file, field: str, frame: int | None = None, match: str | None = None
) -> InputError:
    """Run ``call()``; it must raise :class:`InputError` whose one-line message names ``file``,
    ``field`` (and ``frame`` when given), and must leave ``folder`` exactly as it was."""
    before = _snapshot(folder)
    with pytest.raises(InputError) as info:
        call()
    e = info.value
    msg = str(e)
    assert "\n" not in msg
    assert msg.startswith(f"{file}: "), msg
    assert e.field == field and f": {field}: " in f": {msg}", msg
    if frame is not None:
        assert e.frame == frame and f": frame {frame}: " in msg, msg
    if match is not None:
        assert re.search(match, msg), msg
    assert _snapshot(folder) == before, "a reader wrote files while failing"
    return e
