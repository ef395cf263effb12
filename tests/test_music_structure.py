"""A song's form: generated songs of known form, and the sections ``music.structure`` finds in them."""

from __future__ import annotations

import json
import shutil

import mido
import numpy as np
import pytest
from click.testing import CliRunner

from dancesynth.bench.groundtruth import render_song, section_times, structure_specs, write_midi
from dancesynth.cli import cli
from dancesynth.music import analyze_music
from dancesynth.music.structure import boundaries, novelty, song_structure

needs_fluidsynth = pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")


def _spec(name):
    return next(s for s in structure_specs("tune") if s.name == name)


def _melody_by_bar(path, spec):
    """The lead's (pitch, start in beats) notes of each bar, bars counted after the pickup."""
    mid = mido.MidiFile(path)
    bpb, out = spec.beats_per_bar, {}
    for track in mid.tracks:
        tick = 0
        for msg in track:
            tick += msg.time
            if msg.type == "note_on" and msg.channel == 3:
                beat = tick / mid.ticks_per_beat - spec.pickup_beats
                out.setdefault(int(beat // bpb), []).append((msg.note, round(beat % bpb, 3)))
    return out


def test_a_returning_section_replays_its_melody_and_starts_on_a_downbeat(tmp_path):
    spec = _spec("form-aaba124_4-4")   # V V B V, 8 bars each, after a pickup of 3 beats
    write_midi(spec, tmp_path / "s.mid")
    bars = _melody_by_bar(tmp_path / "s.mid", spec)
    assert [bars[b] for b in range(8)] == [bars[b] for b in range(8, 16)] == [bars[b] for b in range(24, 32)]
    assert [bars[b] for b in range(16, 24)] != [bars[b] for b in range(8)]
    times = section_times(spec)
    assert [t[2] for t in times] == ["V", "V", "B", "V"]
    beat_s = 60.0 / 124
    assert spec.pickup_beats == 3   # the first section takes the pickup; the others start on downbeats
    assert np.allclose([t[0] for t in times], [0] + [(3 + 32 * k) * beat_s for k in (1, 2, 3)], atol=1e-3)


def test_novelty_peaks_where_the_bars_change_on_the_phrase_grid():
    sim = np.full((24, 24), -0.5)
    sim[:12, :12] = sim[12:, 12:] = 1.0
    assert boundaries(novelty(sim)) == [0, 12]
    assert boundaries(novelty(np.ones((24, 24)))) == [0]


def test_a_song_too_short_for_sections_is_one():
    st = song_structure(np.zeros(22050 * 4, np.float32), 22050, np.arange(8) * 0.5, np.arange(8) % 4, 4, 4.0)
    assert len(st.sections) == 1 and st.sections[0].start_s == 0.0 and st.sections[0].end_s == 4.0
    assert song_structure(np.zeros(100, np.float32), 22050, np.zeros(0), None, None, 1.0).sections[0].label == "A"


@needs_fluidsynth
def test_sections_of_a_rendered_song_of_known_form(tmp_path):
    spec = _spec("form-rondo108_3-4")   # V C B C V C, 8 bars each, in 3/4
    song = render_song(spec, tmp_path)
    st = analyze_music(path=song.audio_path, structure=True).structure
    starts = np.array([s.start_s for s in st.sections])
    truth = np.array([s[0] for s in song.sections])
    assert len(starts) == len(truth) and np.all(np.abs(starts - truth) < 0.5)
    labels = [s.label for s in st.sections]
    assert labels[1] == labels[3] == labels[5] and labels[0] == labels[4] and len(set(labels)) == 3
    assert [p.first_bar for p in st.phrases if p.size == 4][:3] == [0, 4, 8]

    out = tmp_path / "beats.json"
    result = CliRunner().invoke(cli, ["beats", str(song.audio_path), "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    # bars numbered as `beats` numbers them: its 2-beat pickup is bar 1, the first downbeat bar 2
    assert [s["label"] for s in data["sections"]] == labels and data["sections"][1]["first_bar"] == 2 + 8
    assert "sections:" in result.output
