"""`dancesynth serve`: the page in headless Chromium (node, playwright-core), dancing a song and live."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC
from serve_support import CLIENTS, TRUMPET, assert_video_with_song, music_http, server  # noqa: F401 (fixtures)

def _browser_missing() -> str | None:
    if not shutil.which("node"):
        return "node is not installed"
    if not Path("/usr/bin/chromium").exists() and not shutil.which("chromium"):
        return "chromium is not installed"
    if not (CLIENTS / "node_modules" / "playwright-core").is_dir():
        return "playwright-core is not installed (cd tests/clients && npm ci)"
    return None


SHOTS = Path("/tmp/web_shots")  # kept after the run, to look at


def run_viewer(server, tmp_path, mode, value, **options):
    """viewer_check.mjs on the page (see its header for ``options``); its report, the screenshots
    copied to SHOTS/<test name>/."""
    chromium = "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else shutil.which("chromium")
    url = f"http://{server[0]}:{server[1]}/"
    proc = subprocess.run(["node", str(CLIENTS / "viewer_check.mjs"), url, str(tmp_path), mode, value, chromium,
                           json.dumps(options)], capture_output=True, text=True, timeout=240, cwd=CLIENTS)
    shots = SHOTS / tmp_path.name
    shutil.copytree(tmp_path, shots, dirs_exist_ok=True, ignore=shutil.ignore_patterns("*.mp4"))
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["ok"], report
    assert not report["errors"], report["errors"]
    assert not report["console"], report["console"]
    assert not report["times"] or report["times"][1] - report["times"][0] > 0.3, "the music clock did not run"
    return report


def stick_pixels(img: np.ndarray) -> np.ndarray:
    """The (orange) stick figure's pixels; the background, grid and ring are not orange."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return (r > 150) & (r - b > 90) & (g > 50) & (g - b > 60)


def srgb(linear: np.ndarray) -> np.ndarray:
    """Linear RGB 0..1 (a vertex colour) as the sRGB the page draws it in, 0..255."""
    return 255 * np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def mannequin_colours() -> np.ndarray:
    """The mannequin mesh's vertex colours as the sRGB the page draws them in, 0..255."""
    from dancesynth.retarget.character import load_character

    return srgb(np.unique(load_character("mannequin").mesh.colours.round(4), axis=0))


def colour_mask(img: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """Pixels of ``colour`` (sRGB) whatever the light: the same hue and saturation (chromaticity within
    0.03), and brighter than the background."""
    chroma = img / np.maximum(img.sum(axis=2, keepdims=True), 1)
    return (img.sum(axis=2) > 120) & (np.linalg.norm(chroma - colour / colour.sum(), axis=2) < 0.03)


def mannequin_pixels(img: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """Pixels of the mannequin's colours, and how many of each colour."""
    masks = [colour_mask(img, c) for c in mannequin_colours()]
    return np.any(masks, axis=0), [int(m.sum()) for m in masks]


def assert_dancing(folder: Path, names=("a", "b"), figure: str = "stick"):
    """The two screenshots show the figure near the centre, in two different poses: the orange stick
    figure, or the mannequin in its own colours (several of them: skin, clothes, shoes) and no stick."""
    from PIL import Image

    a, b = (np.asarray(Image.open(folder / f"{n}.png").convert("RGB")).astype(int) for n in names)
    assert a.shape == b.shape
    h, w, _ = a.shape
    centre = (slice(h // 5, 4 * h // 5), slice(w // 4, 3 * w // 4))
    if figure == "stick":
        fa, fb = stick_pixels(a), stick_pixels(b)
    else:
        (fa, counts_a), (fb, counts_b) = mannequin_pixels(a), mannequin_pixels(b)
        for counts in (counts_a, counts_b):
            assert sum(c > 50 for c in counts) >= 3, f"too few of the mannequin's colours: {counts}"
        assert stick_pixels(a).sum() < 50 and stick_pixels(b).sum() < 50, "the stick figure is drawn too"
    assert fa[centre].sum() > 500 and fb[centre].sum() > 500, f"the {figure} is not drawn near the centre"
    # Moved: its outline changed. (A figure stuck in its rest pose changes 10 % of it, where the beat's ring
    # pulses over its legs; a dancing one 50 % and more.)
    region = fa | fb
    assert (fa ^ fb).sum() > 0.2 * region.sum(), f"the {figure} did not move between the screenshots"

needs_browser = pytest.mark.skipif(_browser_missing() is not None, reason=str(_browser_missing()))


def playing_s(status: str) -> float:
    """The time a "Playing 0:01.2 / 0:05.3 · ..." status line says, in seconds."""
    m = re.match(r"Playing (\d+):(\d+\.\d) / ", status)
    assert m, status
    return 60 * int(m[1]) + float(m[2])


@needs_browser
def test_the_page_dances_to_a_bundled_song_in_headless_chromium(server, tmp_path):
    """The mannequin dances (skinned, in its colours); the stick figure is the other view; the status line
    follows the music: the time advancing while it plays, held when paused, moved by a seek, then finished."""
    report = run_viewer(server, tmp_path, "song", "trumpet", stick=True, playback=True)
    page = report["page"]
    assert page["frames"] == int(sf.info(TRUMPET).duration * 30) + 1
    assert page["dance"]["character"] == "mannequin" and page["dance"]["mesh"]
    assert_dancing(tmp_path, "ab", figure="mannequin")
    assert report["view_after_toggle"] == "stick"
    assert_dancing(tmp_path, "cd", figure="stick")
    st = report["statuses"]
    for shot, t in zip("abcd", report["times"]):
        assert playing_s(st[shot]) == pytest.approx(t, abs=0.25), (st[shot], t)
        assert re.search(r"beat \d+ of 7", st[shot]) and "section" in st[shot]
    assert playing_s(st["b"]) > playing_s(st["a"]) and playing_s(st["d"]) > playing_s(st["c"])
    assert st["paused"].startswith("Paused at 0:01") and st["paused_later"] == st["paused"]
    assert st["seeked"].startswith("Paused at 0:02.0") and "beat 4 of 7" in st["seeked"]
    assert st["finished"].startswith("Finished") and page["playback"]["state"] == "finished"


@needs_browser
def test_the_page_dances_another_engine_on_a_rig_and_downloads_its_video(server, tmp_path):
    """The engine and character chosen on the page are what the server dances (its own record says so);
    a rig without a mesh dances as the stick figure on that rig; the MP4 button renders and downloads."""
    report = run_viewer(server, tmp_path, "song", "trumpet", engine="global", character="mixamo", video=True)
    page = report["page"]
    assert page["dance"]["engine"] == "global" and page["dance"]["character"] == "mixamo"
    assert page["dance"]["joints"][0] == "mixamorig:Hips" and not page["dance"]["mesh"]
    assert page["view"] == "stick"
    assert_dancing(tmp_path, "ab", figure="stick")
    video = report["video"]
    assert video["state"]["state"] == "done" and video["file_name"] == "sorohanro_-_solo-trumpet-06-mixamo.mp4"
    assert any("%" in label or "waiting" in label for label in video["labels"]), video["labels"]
    assert_video_with_song(tmp_path / "dance.mp4")


LIVE_SHOTS = Path("/tmp/web_live_shots")  # the live test's screenshots, kept to look at


def palette_counts(img: np.ndarray) -> dict[str, int]:
    """How many pixels show each of the mannequin's colours by name (skin, top, trousers, shoes, hair)."""
    from dancesynth.retarget.mannequin import PALETTE

    return {name: int(colour_mask(img, srgb(c)).sum()) for name, c in PALETTE.items()}


@needs_browser
def test_the_page_dances_live_to_a_stream_in_headless_chromium(server, music_http, tmp_path):
    """Live, the mannequin dances (its skinned mesh, in its coral top and navy trousers) from the streamed
    frames; the stick figure is still on the toggle; the delay keeps the motion ahead of the music."""
    from PIL import Image

    report = run_viewer(server, tmp_path, "live", f"{music_http}/{TRUMPET.name}", stick=True, pause=True)
    shutil.copytree(tmp_path, LIVE_SHOTS, dirs_exist_ok=True)
    live = report["page"]["live"]
    assert live["character"] == "mannequin" and live["model"] == "ready", live
    assert report["view_live"] == "character"
    assert_dancing(tmp_path, "ab", figure="mannequin")
    for shot in "ab":
        counts = palette_counts(np.asarray(Image.open(tmp_path / f"{shot}.png").convert("RGB")).astype(int))
        assert counts["top"] > 300 and counts["trousers"] > 300, (shot, counts)
    assert report["view_after_toggle"] == "stick"
    assert_dancing(tmp_path, "cd", figure="stick")
    assert live["frames"] > 45 and live["beats"] >= 2
    # The delay the server asks for is enough: the motion of every moment heard had arrived.
    assert live["delay_s"] == pytest.approx(2 + 1.0)
    # Starved only as long as a busy machine made the server later than the delay allows (0 when it kept up).
    assert live["playing_s"] > 0.5 and live["starved_s"] < 0.1 + live["server_late_s"], live
    # Pause holds the live music and dance (a second paused moves the clock by ~0), Resume goes on.
    pause = report["pause"]
    assert pause["label"] == "Resume" and abs(pause["held_for_1s"]) < 0.1 and pause["resumed_1s"] > 0.5, pause
    assert pause["volume"] == pytest.approx(0.3)


@needs_browser
@pytest.mark.parametrize("kind", ["mic", "tab"])
def test_the_page_dances_to_what_it_captures_in_headless_chromium(server, tmp_path, kind):
    """"Dance to the microphone" / "Dance to a tab": Chromium's fake capture device plays a song; the page sends
    it to the server over its WebSocket and the mannequin dances to it, on that song's tempo. Stop (the tab's
    run) ends the capture: the server dances to the end of what it heard and says so."""
    from dancesynth.api import analyse

    song = tmp_path.parent / f"capture-{kind}.wav"   # outside tmp_path: not a shot
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-i", str(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"), "-t", "40", "-ar", "48000", "-ac", "2",
                    str(song)], check=True)
    report = run_viewer(server, tmp_path, "capture", kind, audio_file=str(song),
                        **({"capture_s": 8.0} if kind == "tab" else {}))
    live = report["page"]["live"]
    assert live["capture"]["kind"] == kind and live["capture"]["sent_s"] > 3.0, live
    assert live["model"] == "ready" and report["view_live"] == "character"
    assert_dancing(tmp_path, "ab", figure="mannequin")
    assert live["frames"] > 45 and live["beats"] >= 2
    tempo = analyse(song, structure=False).tempo_bpm
    assert min(abs(live["tempo_bpm"] - tempo * k) for k in (0.5, 1.0, 2.0)) < 0.04 * tempo, (live, tempo)
    # Its sound is not played back (a microphone would hear itself; a tab not muted for us would sound twice).
    assert not live["capture"]["echo"]
    if kind == "tab":
        assert live["state"] == "ended" and "The capture ended" in report["statuses"]["ended"], report["statuses"]
        assert live["summary"]["heard_s"] == pytest.approx(live["capture"]["sent_s"], abs=0.35), live
        assert live["summary"]["frames"] == live["frames"]
    assert "behind the microphone" in report["statuses"]["a"] if kind == "mic" else "behind the tab's sound" in \
        report["statuses"]["a"], report["statuses"]


@needs_browser
def test_the_page_says_so_when_the_browser_refuses_the_microphone(server, tmp_path):
    report = run_viewer(server, tmp_path, "capture", "mic", refuse=True)
    assert "The browser refused the microphone" in report["statuses"]["refused"], report["statuses"]
    assert not report["page"].get("live"), "no live dance starts without the sound"
