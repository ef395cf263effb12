"""Building, storing and caching the motion database and its graphs."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from conftest import REPO
from dancesynth import rotations as rot
from dancesynth.engines.graph.cache import graph_path, load_graph
from dancesynth.engines.graph.meta_graph import GraphConfig
from dancesynth.errors import InputError, ModelError
from dancesynth.motion.database import build_database, load_database, open_database, save_database
from dancesynth.motion.sources import MOTION_SUFFIXES, collect_sources

FIXTURES = REPO / "tests" / "data" / "mocap"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DANCESYNTH_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def small_db():
    return build_database(collect_sources(FIXTURES))


def test_genres_come_from_sub_folders(small_db):
    genres = {s.genre for s in small_db.styles.values()}
    # The 3dsMax fixture is one second of motion: too few beats to dance on, so it is left out.
    assert genres == {"cmu_daz_salsa", "cmu_mb_fbx2bvh"}
    for style in small_db.styles.values():
        assert len(style.beat_frames) >= 3
        assert np.all(np.diff(style.beat_frames) > 0)
        assert style.contacts.shape == (style.n_frames, 2) and style.energy.shape == (style.n_frames,)


def test_a_manifest_assigns_genres(tmp_path):
    folder = tmp_path / "db"
    shutil.copytree(FIXTURES, folder)
    (folder / "genres.toml").write_text('[genres]\nparty = ["cmu_mb_fbx2bvh/*.bvh", "cmu_daz_salsa/*.bvh"]\n')
    genres = {g for g, _ in collect_sources(folder)}
    assert genres == {"party"}
    (folder / "genres.toml").write_text("this is not toml = [")
    with pytest.raises(InputError, match="genres manifest"):
        collect_sources(folder)
    # Issue 13: valid TOML of the wrong shape was an internal error (TypeError, AttributeError).
    for wrong in ("genres = 3", "[genres]\nsalsa = 5", '[genres]\nsalsa = [5, "cmu_daz_salsa/*.bvh"]'):
        (folder / "genres.toml").write_text(wrong + "\n")
        with pytest.raises(InputError, match="must be a table of genre"):
            collect_sources(folder)


def test_a_one_frame_clip_in_a_database_folder_is_left_out(tmp_path):
    """Issue 13: a clip too short to hold a beat was an internal error (numpy's gradient of one frame)."""
    folder = tmp_path / "db"
    shutil.copytree(FIXTURES / "cmu_daz_salsa", folder / "salsa")
    head, motion = next((folder / "salsa").glob("*.bvh")).read_text().split("MOTION", 1)
    frame_time, first = motion.strip().splitlines()[1:3]
    (folder / "salsa" / "one_frame.bvh").write_text(f"{head}MOTION\nFrames: 1\n{frame_time}\n{first}\n")
    db = build_database(collect_sources(folder))
    assert "one_frame" not in {name for st in db.styles.values() for name in st.clip_names}
    assert sum(st.n_clips for st in db.styles.values()) == len(list(FIXTURES.glob("cmu_daz_salsa/*.bvh")))


def test_save_and_load_keep_the_motion(small_db, tmp_path):
    save_database(small_db, tmp_path / "db")
    loaded = load_database(tmp_path / "db")
    assert set(loaded.styles) == set(small_db.styles)
    for name, a in small_db.styles.items():
        b = loaded.styles[name]
        assert b.skeleton.names == a.skeleton.names
        assert np.array_equal(b.beat_frames, a.beat_frames)
        assert np.degrees(rot.angle(a.local_rot.astype(float), b.local_rot.astype(float))).max() < 0.01
        assert np.allclose(a.root_pos, b.root_pos)


def test_a_corrupt_database_is_a_clear_error(small_db, tmp_path):
    save_database(small_db, tmp_path / "db")
    victim = next((tmp_path / "db").glob("*.npz"))
    victim.write_bytes(victim.read_bytes()[:100])
    with pytest.raises(ModelError, match="rebuild"):
        load_database(tmp_path / "db")
    with pytest.raises(InputError, match="not a dancesynth database"):
        load_database(tmp_path)


def test_the_bundled_database_ships_its_licences():
    from dancesynth.motion.database import BUNDLED_DATABASE

    text = (BUNDLED_DATABASE / "README.md").read_text()
    assert "mocap.cs.cmu.edu" in text and "NSF EIA-0196217" in text
    assert (BUNDLED_DATABASE / "LICENSES" / "CMU_LICENSE.txt").is_file()
    assert (BUNDLED_DATABASE / "LICENSES" / "G1-Moves_DATASET_CARD.md").is_file()       # CC BY 4.0
    assert (BUNDLED_DATABASE / "LICENSES" / "unitree_ros_LICENSE_BSD-3-Clause.txt").is_file()
    size = sum(p.stat().st_size for p in BUNDLED_DATABASE.rglob("*") if p.is_file())
    assert size < 30e6


def test_graphs_are_cached_and_rebuilt_when_anything_changes(perfume_db, bundled_db, cache):
    style = perfume_db.styles["jpop"]
    g1, cached1 = load_graph(style)
    g2, cached2 = load_graph(style)
    assert (cached1, cached2) == (False, True)
    assert np.array_equal(g1.bi_src, g2.bi_src) and np.array_equal(g1.capacity, g2.capacity)
    # Another parameter: another cache entry, built afresh.
    _, cached3 = load_graph(style, GraphConfig(ths=2.0))
    assert not cached3
    # Changed content (a new fingerprint): rebuilt.
    from dataclasses import replace

    changed = replace(style, fingerprint=style.fingerprint + "-edited")
    assert graph_path(changed, GraphConfig()) != graph_path(style, GraphConfig())
    assert not load_graph(changed)[1]
    # A damaged cache file is rebuilt, not trusted.
    path = graph_path(style, GraphConfig())
    path.write_bytes(b"garbage")
    g4, cached4 = load_graph(style)
    assert not cached4 and np.array_equal(g4.bi_src, g1.bi_src)


def test_a_folder_of_bvh_is_built_once_and_rebuilt_after_an_edit(tmp_path, cache):
    folder = tmp_path / "mine"
    shutil.copytree(FIXTURES / "cmu_daz_salsa", folder / "salsa")
    first = open_database(folder)
    again = open_database(folder)
    assert again.styles["salsa"].fingerprint == first.styles["salsa"].fingerprint
    built = list((cache / "databases").iterdir())
    assert len(built) == 1
    bvh = next((folder / "salsa").glob("*.bvh"))
    os.utime(bvh, (bvh.stat().st_atime, bvh.stat().st_mtime + 10))
    open_database(folder)
    assert len(list((cache / "databases").iterdir())) == 2


def test_the_database_reads_every_suffix_the_motion_readers_know():
    from dancesynth.io.motion_files import MOTION_SUFFIXES as READERS

    assert MOTION_SUFFIXES == READERS
