"""`dancesynth serve`'s live dances: /ws/live streams audio, the hierarchy, frames and beats over WebSocket
(the rest of the web API: test_serve.py)."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC
from serve_support import TRUMPET, capture_session, live_messages, music_http, request, server, song_pcm  # noqa: F401
from servers import uvicorn_server


def test_live_streams_audio_hierarchy_frames_and_beats(server, music_http):
    """One viewer on the default character (the mannequin) and, at the same time, one of the same stream
    on another: two broadcasts, each on its character's rig."""
    from urllib.parse import urlencode

    from dancesynth.io.bvh import parse_bvh
    from dancesynth.retarget.rigs import rig_skeleton

    url = f"{music_http}/{TRUMPET.name}"
    t0 = time.monotonic()
    on_cmu = {}
    other = threading.Thread(target=lambda: on_cmu.update(
        zip(("messages", "audio"), live_messages(server, urlencode({"url": url, "segment_s": 2, "character": "cmu"})))))
    other.start()
    streams = []

    def poll_streams():
        while other.is_alive():
            streams.append(json.loads(request(server, "GET", "/api/live")[2])["streams"])
            time.sleep(0.5)

    poller = threading.Thread(target=poll_streams)
    poller.start()
    try:
        messages, audio = live_messages(server, urlencode({"url": url, "segment_s": 2}))
    finally:
        other.join(timeout=60)
        poller.join(timeout=10)
    kinds = [m["type"] for m in messages]
    assert kinds[0] == "start" and kinds[-1] == "end", messages[-1]
    assert kinds.count("hierarchy") == 1 and kinds.index("hierarchy") < kinds.index("frames")
    duration = sf.info(TRUMPET).duration
    assert time.monotonic() - t0 > 0.8 * duration, "a stream plays at its own pace"
    assert audio == pytest.approx(duration * 22050 * 2, rel=0.02)
    frames = [m for m in messages if m["type"] == "frames"]
    assert len(frames) >= 2
    assert [f["start_frame"] for f in frames] == list(np.cumsum([0] + [len(f["rows"]) for f in frames[:-1]]))
    hierarchy = next(m for m in messages if m["type"] == "hierarchy")
    rows = [r for f in frames for r in f["rows"]]
    text = "\n".join([hierarchy["bvh"], "MOTION", f"Frames: {len(rows)}", "Frame Time: 0.03333333", *rows])
    clip = parse_bvh(text)
    assert clip.n_frames == len(rows) == messages[-1]["summary"]["frames"]
    assert abs(clip.n_frames / 30 - duration) < 0.5
    beats = [t for m in messages if m["type"] == "beats" for t in m["beats"]]
    assert len(beats) >= 3 and np.all(np.diff(beats) > 0)
    # Retargeted onto the mannequin: its rig in the header (the joints the page's GLB has), standing on the floor.
    assert messages[0]["character"] == "mannequin"
    assert sorted(clip.skeleton.names) == sorted(rig_skeleton("mannequin")[0].names)
    assert 0.7 < clip.root_pos[:, 1].mean() < 1.1, "the hips are not at the mannequin's height"
    # The other viewer chose cmu: its own broadcast, on the cmu rig, beside the mannequin's.
    others = on_cmu["messages"]
    assert others[0]["character"] == "cmu" and others[-1]["type"] == "end", others[-1]
    cmu = next(m for m in others if m["type"] == "hierarchy")["bvh"]
    assert "LHipJoint" in cmu and "LHipJoint" not in hierarchy["bvh"]
    assert any(sorted((s["character"], s["viewers"]) for s in seen) == [("cmu", 1), ("mannequin", 1)]
               for seen in streams), streams


def test_a_client_that_leaves_mid_stream_stops_the_live_dance(server, music_http):
    from urllib.parse import urlencode

    from websockets.sync.client import connect

    query = urlencode({"url": f"{music_http}/Kevin_MacLeod_-_Vibe_Ace.ogg", "segment_s": 2})
    with connect(f"ws://{server[0]}:{server[1]}/ws/live?{query}", open_timeout=10, max_size=None) as ws:
        assert json.loads(ws.recv(timeout=10))["type"] == "start"
        for _ in range(5):
            ws.recv(timeout=10)  # some audio
    deadline = time.monotonic() + 20
    while any(t.name == "dancesynth-live" for t in threading.enumerate()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(t.name == "dancesynth-live" for t in threading.enumerate()), "the live thread kept running"
    status, _, _ = request(server, "GET", "/api/songs")
    assert status == 200


@pytest.mark.parametrize("query, words", [
    ("url=/etc/passwd", "http"), ("url=-", "http"), ("", "http"),
    ("url=http://127.0.0.1:9/x.ogg&segment_s=abc", "segment_s"),
    ("url=http://127.0.0.1:9/nothing.ogg", "no audio"),
    ("url=http://127.0.0.1:9/x.ogg&character=robot", "unknown character 'robot'; pick one of mannequin"),
    ("url=http://127.0.0.1:9/x.ogg&character=/etc/passwd", "unknown character"),
    ("url=http://127.0.0.1:9/x.ogg&character=tests%2Fdata%2Fa.bvh", "unknown character"),
])
def test_live_refuses_bad_streams_with_a_message(server, query, words):
    messages, _ = live_messages(server, query, timeout_s=30)
    assert messages[-1]["type"] == "error", messages
    assert words in messages[-1]["error"]


def test_live_audio_is_relayed_in_pieces_and_nothing_is_held_back():
    """The stream's ~20 ms reads go to the viewers in pieces of at least RELAY_S (fewer sends for 50 viewers);
    a read that finds nothing (a stall) and the end hand on what is held, so no audio waits or is lost."""
    from types import SimpleNamespace

    from dancesynth.web.live import RELAY_S, _RelaySource

    sr = 22050
    reads = [np.full(441, 0.5, np.float32)] * 7 + [None] + [np.full(441, -0.25, np.float32)] * 3

    class Source:
        sr, spec, error = 22050, "test", ""

        def read(self, timeout):
            if not reads:
                raise StopIteration
            samples = reads.pop(0)
            return None if samples is None else SimpleNamespace(samples=samples)

    sent = []
    relay = _RelaySource(Source(), sent.append, int(RELAY_S * sr))
    with pytest.raises(StopIteration):
        while True:
            relay.read(0.05)
    pieces = [np.frombuffer(b, "<i2") for b in sent]
    assert [len(x) for x in pieces] == [2205, 882, 1323]  # 5 reads; the 2 before the stall; the 3 before the end
    assert np.all(pieces[0] == 16383) and np.all(pieces[2] == -8191)


def test_a_page_capture_is_danced_on_its_own_beat(server):
    """What a page captures and sends (here 12 s of Vibe Ace at 44.1 kHz, at real-time pace) is danced on the
    song's tempo, its sound relayed back whole (resampled), and the dance ends when the page says so."""
    from dancesynth.api import analyse

    song = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
    seen = []

    def watch_status(messages):
        if len(seen) < 1 and any(m["type"] == "frames" for m in messages):
            seen.append(json.loads(request(server, "GET", "/api/live")[2])["streams"])
        return False

    messages, audio = capture_session(server, "source=mic&rate=44100&segment_s=3", song_pcm(song, 44100, 12.0),
                                      44100, until=watch_status)
    kinds = [m["type"] for m in messages]
    assert kinds[0] == "start" and kinds[-1] == "end", messages[-1]
    assert audio / 2 == pytest.approx(12.0 * 22050, abs=50)
    frames = sum(len(m["rows"]) for m in messages if m["type"] == "frames")
    assert frames == messages[-1]["summary"]["frames"] and abs(frames / 30 - 12.0) < 0.5
    tempo = messages[-1]["summary"]["tempo_bpm"]
    song_tempo = analyse(song, structure=False).tempo_bpm
    assert min(abs(tempo - song_tempo * k) for k in (0.5, 1.0, 2.0)) < 0.04 * song_tempo, (tempo, song_tempo)
    assert [s["url"] for s in seen[0]] == ["mic capture from 127.0.0.1"], seen


@pytest.mark.parametrize("query, pcm_s, pace, piece_s, words", [
    ("source=tab&rate=48000", 6.0, 4.0, 0.1, "faster than real time"),
    ("source=tab&rate=48000", 3.0, 1.0, 1.5, "at most 1 s a message"),
    ("source=radio&rate=48000", 1.0, 1.0, 0.1, "source must be tab or mic"),
    ("source=mic&rate=44.1", 1.0, 1.0, 0.1, "rate must be"),
    ("source=mic&rate=1000000", 1.0, 1.0, 0.1, "rate must be"),
    ("source=mic&rate=48000&character=/etc/passwd", 1.0, 1.0, 0.1, "unknown character"),
])
def test_a_page_capture_out_of_bounds_ends_with_why(server, query, pcm_s, pace, piece_s, words):
    pcm = song_pcm(TRUMPET, 48000, pcm_s)
    messages, _ = capture_session(server, query, pcm, 48000, pace=pace, piece_s=piece_s, timeout_s=30)
    assert messages[-1]["type"] == "error", messages[-1]
    assert words in messages[-1]["error"], messages[-1]


def test_one_capture_per_client_and_the_capture_limit(tmp_path):
    """A second capture from the same computer is refused while the first runs; a capture ends, with a
    message, at the server's length limit; a page that goes away stops its dance."""
    from websockets.sync.client import connect

    from dancesynth.web.server import create_app

    with uvicorn_server(create_app(max_capture_s=3.0)) as address:
        pcm = song_pcm(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg", 48000, 6.0)
        query = "source=mic&rate=48000&segment_s=2"
        with connect(f"ws://{address[0]}:{address[1]}/ws/live?{query}", open_timeout=10) as first:
            assert json.loads(first.recv(timeout=10))["type"] == "start"
            second, _ = capture_session(address, query, pcm[:9600], 48000, timeout_s=10)
            assert "already sends the server a live source" in second[-1]["error"]
        deadline = time.monotonic() + 20   # the first went away: its dance stops, and a new capture may start
        while json.loads(request(address, "GET", "/api/live")[2])["streams"] and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not json.loads(request(address, "GET", "/api/live")[2])["streams"], "the capture kept dancing"
        messages, audio = capture_session(address, query, pcm, 48000, timeout_s=30)
        assert messages[-1]["type"] == "error" and "at most 0.05 min" in messages[-1]["error"], messages[-1]
        assert 2.5 < audio / 2 / 22050 <= 3.1
