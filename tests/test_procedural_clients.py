"""The conducting character's BVH imports in Blender and three.js like every other output."""

from __future__ import annotations

import pytest
from procedural_songs import phrase_song
from test_bvh_clients import check_blender, check_three, needs_blender, needs_three

from dancesynth.api import conduct
from dancesynth.io.bvh import read_bvh, write_bvh
from dancesynth.kinematics import clip_fk


@pytest.fixture(scope="module")
def conducted(tmp_path_factory):
    d = tmp_path_factory.mktemp("conduct")
    out = d / "phrases.bvh"
    write_bvh(out, conduct(phrase_song(d / "phrases.mid")))
    written = read_bvh(out)
    return written, out, clip_fk(written)[1]


@pytest.mark.blender
@needs_blender
def test_blender_imports_a_conducted_song(conducted, tmp_path):
    clip = conducted[0]
    check_blender(*conducted, tmp_path, (0, clip.n_frames // 2, clip.n_frames - 1))


@needs_three[0]
@needs_three[1]
def test_threejs_imports_a_conducted_song(conducted):
    clip = conducted[0]
    check_three(*conducted, (0, clip.n_frames // 2, clip.n_frames - 1))
