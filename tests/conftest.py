"""Shared test fixtures: where the bundled and the shared data live."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE_DATA = REPO / "src" / "dancesynth" / "data"
BUNDLED_MUSIC = PACKAGE_DATA / "music"
# The team's shared data folder sits beside the repository; CI machines have it too.
_CANDIDATES = [os.environ.get("DANCESYNTH_SHARED"), REPO.parent / "shared", "/work/shared"]
SHARED = next((Path(c) for c in _CANDIDATES if c and (Path(c) / "data" / "mocap").is_dir()), REPO.parent / "shared")
SHARED_MOCAP = SHARED / "data" / "mocap"

os.environ.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
# Graphs and user databases built by tests go to the repository's cache, not the user's.
os.environ.setdefault("DANCESYNTH_CACHE", str(REPO / ".cache" / "dancesynth"))


def shared_mocap_files():
    return sorted(SHARED_MOCAP.glob("*/*.bvh")) if SHARED_MOCAP.is_dir() else []


requires_shared = pytest.mark.skipif(not SHARED_MOCAP.is_dir(), reason=f"shared mocap not found at {SHARED_MOCAP}")


@pytest.fixture(scope="session")
def bundled_song():
    return BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"


@pytest.fixture(scope="session")
def bundled_db():
    from dancesynth.motion.database import open_database

    return open_database()


@pytest.fixture(scope="session")
def perfume_db(tmp_path_factory):
    """The Perfume Dev Team's three J-pop clips as a database of one style, ``jpop``. They left the
    bundled database (their performance data is not ours to redistribute) but remain the suite's
    real capture on a 23-joint Perfume skeleton, read from the shared folder."""
    import shutil

    from dancesynth.motion.database import open_database

    if not SHARED_MOCAP.is_dir():
        pytest.skip(f"shared mocap not found at {SHARED_MOCAP}")
    folder = tmp_path_factory.mktemp("perfume") / "db"
    shutil.copytree(SHARED_MOCAP / "perfume_mit", folder / "jpop")
    return open_database(folder)
