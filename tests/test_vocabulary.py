"""What the database dances: the G1 robot read as a humanoid, only shippable data, material-aware style
choice, repetition measured, licences listed, the song's genre tag followed."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from conftest import PACKAGE_DATA, REPO, SHARED_MOCAP, requires_shared
from dancesynth.engines.beatgrid import MIN_MATERIAL_MINUTES, genre_preference, style_fits, tempo_map
from dancesynth.errors import InputError, ModelError
from dancesynth.eval.artefacts import one_frame_steps
from dancesynth.eval.repetition import repetition
from dancesynth.motion.database import MotionDatabase
from test_cli import cli, run

G1 = SHARED_MOCAP / "g1_moves_ccby"
CHAINS = REPO / "scripts" / "g1_chains.toml"
DATABASE = PACKAGE_DATA / "database"


@pytest.fixture(scope="module")
def g1_clip():
    from dancesynth.io.bvh import read_bvh

    if not G1.is_dir():
        pytest.skip("shared G1 Moves not found")
    return read_bvh(G1 / "J_Dance5_Hype.bvh")


# -- the robot skeleton ---------------------------------------------------------------------------------------


def test_the_g1_robot_skeleton_is_read_as_a_humanoid_within_two_centimetres(g1_clip):
    from dancesynth.motion.chains import collapse, read_chain_map
    from dancesynth.motion.roles import find_roles
    from dancesynth.retarget.humanoid import find_bones

    with pytest.raises(ModelError, match="chain map"):
        find_roles(g1_clip.skeleton)              # by name alone: no legs (its joints are named for their axes)
    clip = collapse(g1_clip, read_chain_map(CHAINS))
    assert clip.n_frames == g1_clip.n_frames and clip.skeleton.n_joints == 19
    assert max(clip.meta["fit_errors"].values()) < 0.02            # joints where the robot's are, to 2 cm RMS
    bones = find_bones(clip.skeleton)
    roles = find_roles(clip.skeleton)
    assert roles.toes[0] == clip.skeleton.index("leftToes") and bones["neck"] == clip.skeleton.index("neck")
    from dancesynth.kinematics import fk

    _, pos = fk(clip.local_rot, clip.root_pos, clip.skeleton.offsets, clip.skeleton.parents)
    head, feet = pos[:, bones["head"], 1], pos[:, [bones["leftFoot"], bones["rightFoot"]], 1].max(axis=1)
    assert np.all(head - feet > 0.6)           # upright all through the dance: a 1.3 m robot's head over its feet


def test_a_chain_map_naming_a_missing_joint_is_a_clear_error(g1_clip, tmp_path):
    from dancesynth.motion.chains import collapse, parse_chain_map, read_chain_map

    bad = tmp_path / "bad.toml"
    bad.write_text('[chains]\nhips = ["pelvis"]\nleftUpperLeg = ["no_such_link"]\n')
    with pytest.raises(InputError, match="no_such_link"):
        collapse(g1_clip, read_chain_map(bad))
    with pytest.raises(InputError, match="unknown bone"):
        parse_chain_map({"hips": ["pelvis"], "tail": ["x"]})
    with pytest.raises(InputError, match="metres"):
        parse_chain_map({"hips": ["pelvis"], "head": {"joints": ["x"], "at": [0, "up", 0]}})


def test_one_frame_snaps_are_mended_and_the_motion_around_them_kept(g1_clip):
    from dancesynth import rotations as rot
    from dancesynth.motion.chains import collapse, read_chain_map
    from dancesynth.motion.cleanup import remove_snaps

    clip = collapse(g1_clip, read_chain_map(CHAINS)).frames(0, 600)
    mended, _ = remove_snaps(clip)
    assert len(one_frame_steps(mended, threshold_deg=30)) == 0
    # a 60-degree flip of the left elbow at frame 300, staying flipped: the retarget glitch G1 Moves has
    q = clip.local_rot.copy()
    j = clip.skeleton.index("leftLowerArm")
    q[301:, j] = rot.mul(rot.exp(np.array([np.radians(60), 0, 0])), q[301:, j])
    broken = type(clip)(clip.skeleton, clip.fps, clip.root_pos, q)
    assert any(f == 300 and jj == j for f, jj in one_frame_steps(broken, threshold_deg=30))
    fixed, n = remove_snaps(broken)
    assert n >= 1 and not any(jj == j for _, jj in one_frame_steps(fixed, threshold_deg=30))
    far = np.r_[0:280, 330:600]          # more than the 0.1 s window away: untouched
    np.testing.assert_allclose(np.abs(np.sum(fixed.local_rot[far, j] * mended.local_rot[far, j], axis=-1))[:280],
                               1.0, atol=1e-6)


@requires_shared
def test_build_db_reads_g1_clips_with_the_chain_map_and_refuses_them_without(tmp_path):
    folder = tmp_path / "mine"
    (folder / "pop").mkdir(parents=True)
    for name in ("J_ShortDance13_SingleLadies.bvh", "J_ShortDance16_JazzWalk.bvh"):
        shutil.copy(G1 / name, folder / "pop" / name)
    out = tmp_path / "db"
    proc = run("build-db", folder, "-o", out)
    assert proc.returncode != 0 and "chain map" in proc.stderr and not out.exists()
    shutil.copy(CHAINS, folder / "g1_chains.toml")
    (folder / "genres.toml").write_text('[genres]\npop = ["pop/*.bvh"]\n[rigs.g1]\nfiles = ["pop/*.bvh"]\n'
                                        'chains = "g1_chains.toml"\nmend_snaps = true\n'
                                        '[licences.g1]\nfiles = ["pop/*.bvh"]\nlicence = "CC BY 4.0"\n')
    proc = run("build-db", folder, "-o", out)
    assert proc.returncode == 0, proc.stderr
    proc = run("styles", "--database", out)
    assert proc.returncode == 0 and "pop" in proc.stdout and "CC BY 4.0" in proc.stdout


# -- what ships ------------------------------------------------------------------------------------------------


def test_the_bundle_ships_only_redistributable_data_and_credits_every_clip(bundled_db):
    assert "jpop" not in bundled_db.genres()
    attribution = (DATABASE / "ATTRIBUTION.md").read_text()
    for st in bundled_db.styles.values():
        assert set(st.licences) <= {"CMU", "CC BY 4.0"}, st.name
        for clip, src in zip(st.clip_names, st.clip_sources):
            assert f"| {st.name} | {clip} | {src} |" in attribution
    assert "mocap.cs.cmu.edu" in attribution and "Jasmine Coro" in attribution
    assert not any("perfume" in p.name.lower() for p in (DATABASE / "LICENSES").iterdir())
    minutes = {g: sum(s.duration_s for s in bundled_db.styles_of(g)) / 60 for g in bundled_db.genres()}
    assert sum(minutes.values()) >= 30 and minutes["salsa"] >= 10 and minutes["pop"] >= 10
    assert sum(s.duration_s >= 120 for s in bundled_db.styles.values()) >= 4


def test_styles_lists_licence_and_captured_and_mirrored_minutes():
    proc = run("styles")
    assert proc.returncode == 0, proc.stderr
    header, *rows = proc.stdout.splitlines()
    assert "minutes" in header and "mirrored" in header and "licence" in header
    pop = next(r for r in rows if r.startswith("pop-100-124bpm"))
    assert pop.rstrip().endswith("CC BY 4.0")
    assert "minutes of captured dance" in rows[-1]


def test_the_tempo_map_has_five_minutes_of_material_nearly_everywhere(bundled_db):
    rows = tempo_map(bundled_db, range(60, 181))
    best = {r["tempo_bpm"]: max([x["minutes"] for x in r["styles"]] or [0]) for r in rows}
    assert all(best[t] >= MIN_MATERIAL_MINUTES for t in range(60, 181))
    assert sum(best[t] >= 5 for t in range(70, 181)) >= 105
    proc = run("styles", "--tempo-map", "--step", "30")
    assert proc.returncode == 0, proc.stderr
    assert [line.split()[0] for line in proc.stdout.splitlines()[1:]] == ["60", "90", "120", "150", "180"]


# -- choosing a style --------------------------------------------------------------------------------------------


def test_a_style_under_two_minutes_is_never_chosen_unless_named(bundled_db):
    small = [s.name for s in bundled_db.styles.values() if s.duration_s < 120]
    assert {"whirl", "indian", "mj"} <= set(small)
    for bpm in range(60, 181, 3):                 # whirl (81 bpm), mj (~95), indian (157) fit some of these best
        fit = style_fits(bundled_db, np.full(64, 60.0 / bpm))[0]
        assert fit.style.name not in small and fit.material_minutes >= MIN_MATERIAL_MINUTES, bpm
    named = style_fits(bundled_db, np.full(64, 60.0 / 81), "whirl")[0]
    assert named.style.name == "whirl" and named.forced
    # a database of small styles only: the best of them, not an error
    tiny = MotionDatabase({n: bundled_db.styles[n] for n in small})
    assert style_fits(tiny, np.full(64, 60.0 / 81))[0].style.name in small


def test_a_named_small_style_reports_how_often_its_material_repeats(tmp_path, bundled_song):
    report = tmp_path / "r.json"
    proc = run("dance", bundled_song, "--style", "whirl", "-o", tmp_path / "d.bvh", "--report", report)
    assert proc.returncode == 0, proc.stderr
    rep = json.loads(report.read_text())["summary"]["repetition"]
    assert rep["material_minutes"] < 0.5 and rep["replayed_share"] > 0.3    # a 20-second clip over a minute
    assert f"{rep['replayed_share']:.0%} of the beats replay" in proc.stdout


def test_repetition_counts_a_known_loop():
    times = np.arange(96) * 0.5                   # 48 s at 120 bpm
    fresh = [("a", k) for k in range(96)]
    assert repetition(fresh, times)["replayed_share"] == 0.0
    loop = [("a", k % 8) for k in range(96)]      # one 8-beat phrase, looped
    r = repetition(loop, times)
    assert r["replayed_share"] == pytest.approx(88 / 96) and r["longest_repeat_beats"] == 88
    assert r["distinct_source_beats"] == 8
    # beats danced more than 60 s apart do not count as a replay
    assert repetition([("a", 0), ("a", 0)], [0.0, 61.0])["replayed_share"] == 0.0


def test_the_report_says_which_clip_and_frame_every_music_beat_was_danced_from(tmp_path, bundled_song, bundled_db):
    report = tmp_path / "r.json"
    assert run("dance", bundled_song, "-o", tmp_path / "d.bvh", "--report", report).returncode == 0
    data = json.loads(report.read_text())
    sources = data["music_beat_sources"]
    assert len(sources) == len(data["music_beat_times_s"])
    st = bundled_db.styles[data["style"]]
    lengths = dict(zip(st.clip_names, np.diff(st.clip_starts)))
    assert all(0 <= s["frame"] < lengths[s["clip"]] for s in sources)
    assert {s["file"] for s in sources} <= set(st.clip_sources)
    ids = [(s["clip"], s["source_beat"]) for s in sources]
    assert repetition(ids, data["music_beat_times_s"])["replayed_share"] == \
        pytest.approx(data["summary"]["repetition"]["replayed_share"])


# -- the song's genre tag ---------------------------------------------------------------------------------------


def test_genre_tags_map_onto_the_database_genres(bundled_db):
    assert genre_preference(bundled_db, "Hip-Hop")[0] == "pop"
    assert genre_preference(bundled_db, "Salsa")[0] == "salsa"
    assert genre_preference(bundled_db, "Polka") == ()
    assert genre_preference(bundled_db, None) == ()


def test_a_tagged_song_is_danced_in_its_genre_when_that_fits_the_tempo(tmp_path):
    from dancesynth.bench.groundtruth import SongSpec, render_song

    song = render_song(SongSpec("tag110", (110,), duration_s=30.0, seed=3), tmp_path)
    untagged, hiphop = tmp_path / "plain.ogg", tmp_path / "hiphop.ogg"
    for path, extra in ((untagged, []), (hiphop, ["-metadata", "genre=Hip-Hop"])):
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-i", str(song.audio_path), *extra, str(path)],
                       check=True)
    plain = cli("dance", untagged, "-o", tmp_path / "a.bvh", "--report", tmp_path / "a.json")
    tagged = cli("dance", hiphop, "-o", tmp_path / "b.bvh", "--report", tmp_path / "b.json")
    assert plain.returncode == tagged.returncode == 0
    a, b = (json.loads((tmp_path / n).read_text())["summary"] for n in ("a.json", "b.json"))
    assert b["genre"] == "pop" and "Hip-Hop" in b["style_reason"] and "genre tag" in tagged.stdout
    assert a["style_reason"].startswith("it fits the song's tempo best")
    assert b["in_range_expected"] >= 0.85
