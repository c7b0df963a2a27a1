"""The first run says that it compiles the kernels, once."""

from __future__ import annotations

import re
import subprocess

import pytest

from popdispatch.compile_notice import kernels_cached

from test_commands import clean_env, command

NOTICE = "compiling the engine's kernels"


def test_the_cache_check_reads_numbas_index():
    # None would mean numba's cache internals moved and the notice silently never shows
    assert kernels_cached() in (True, False)


@pytest.mark.slow
def test_compile_notice_only_when_numbas_cache_is_cold(tmp_path):
    """An empty NUMBA_CACHE_DIR compiles and says so (that the run takes longer, once per
    configuration, and that later runs load the kernels from the cache); the next run loads
    them from that cache and says nothing. ``-q`` is left out: the notice is a note."""
    env = {**clean_env(), "NUMBA_CACHE_DIR": str(tmp_path)}
    args = command("day", "--mode", "exact", "--minutes", "600-601", "--json")
    runs = [
        subprocess.run(args, capture_output=True, text=True, env=env, timeout=900) for _ in range(2)
    ]
    for result in runs:
        assert result.returncode == 0, result.stderr
    cold, warm = runs
    assert cold.stderr.count(NOTICE) == 1, cold.stderr
    said = " ".join(cold.stderr.split())
    assert re.search(r"takes longer, once per configuration; later runs load them from numba's "
                     r"disk cache", said), cold.stderr  # fmt: skip
    assert NOTICE not in warm.stderr, warm.stderr
    assert any(tmp_path.rglob("*.nbi"))  # the kernels went where we looked
