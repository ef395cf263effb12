"""Every parameter of the procedural dancer's look, with one source of defaults.

Loi & Li leave the look to the user (their Fig. 9 GUI): the segmentation weights
w1..w4 and ideals of eq. (1)-(5), the corner distances L1, L2 and the bounce of
Fig. 6, the hand's speed limit. We add the sizes the paper fixes implicitly
(sweep width, metres per semitone) and the left hand, head and torso amounts of
§V.G. A *style* is a named set of overrides; a TOML file may name a style and
override any field; ``--param name=value`` overrides last.
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from ...errors import InputError
from ...types import DEFAULT_FPS


@dataclass(frozen=True)
class ProceduralConfig:
    """Parameters of ``dancesynth conduct``.

    Lengths are in *arm lengths* (shoulder to wrist), so a look carries over to any
    skeleton; speeds in arm lengths per second, times in seconds, angles in degrees.
    """

    # Segmentation, eq. (1)-(5): weights and ideals.
    w1: float = 1.0                 # the segment ends on a beat or a rest
    w2: float = 0.5                 # pitch range near the ideal
    w3: float = 0.3                 # beat density near the song's
    w4: float = 1.0                 # duration near the ideal
    ideal_range: float = 12.0       # semitones
    ideal_duration: float = 16.0    # sixteenth notes (one 4/4 bar)
    max_segment_notes: int = 48     # bound on a segment's length in notes (keeps the DP fast)
    # Keyframes, eq. (6)-(8).
    sweep_width: float = 0.8        # X_scale: horizontal span of one segment
    y_scale: float = 0.035          # Y_scale: height per semitone, at mid intensity
    intensity_gain: float = 0.5     # louder notes move further vertically (0: not at all)
    # Corners of Fig. 6 and speed of Fig. 7.
    l1: float = 0.25                # distance to G1 along the way out (capped by the speed limit)
    l2: float = 0.25                # distance to G2, the rebound upwards
    bounce: float = 0.6             # how far P1 goes towards the reflection of P2 (0..1)
    speed_limit: float = 5.0        # the hand's fastest (about 2.2 m/s for a 0.45 m arm)
    beat_acceleration: float = 2.0  # speed on arriving at a beat note, times the piece's mean speed (<= 3)
    # Arms: reach and joint limits.
    reach: float = 0.9              # fraction of the arm's length the hand may be from the shoulder
    elbow_min: float = 10.0         # elbow flexion limits
    elbow_max: float = 140.0
    swivel: float = 20.0            # elbow turned out from straight down
    # Left hand (§V.G).
    long_note: float = 4.0          # sixteenths: notes longer than a quarter of a whole note are long
    extend: float = 1.0             # how far towards full extension the left hand reaches on a long note
    staccato_drop: float = 0.25     # how far it drops on a staccato note
    # Head and torso (§V.G).
    nod: float = 8.0                # head nod on a beat
    sway: float = 5.0               # torso swing to each side
    nod_turn: float = 0.25          # least time between two changes of direction of the head
    sway_turn: float = 0.6          # ... and of the torso
    knee_bend: float = 8.0          # the legs' easy stance
    fps: float = DEFAULT_FPS

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or v != v or abs(v) == float("inf"):
                raise InputError(f"parameter {f.name} must be a finite number, got {v!r}")
        for name in ("w1", "w2", "w3", "w4", "l1", "l2", "intensity_gain", "extend", "staccato_drop", "nod",
                     "sway", "nod_turn", "sway_turn", "knee_bend", "swivel"):
            if getattr(self, name) < 0:
                raise InputError(f"parameter {name} must be 0 or more, got {getattr(self, name)}")
        checks = [
            (self.w1 + self.w2 + self.w3 + self.w4 > 0, "the weights w1..w4 cannot all be 0"),
            (self.ideal_range > 0 and self.ideal_duration > 0, "ideal_range and ideal_duration must be positive"),
            (2 <= self.max_segment_notes <= 500, "max_segment_notes must be between 2 and 500"),
            (0 < self.sweep_width <= 1.2, "sweep_width must be between 0 and 1.2 arm lengths"),
            (0 <= self.y_scale <= 0.2, "y_scale must be between 0 and 0.2 arm lengths per semitone"),
            (self.l1 <= 1 and self.l2 <= 1, "l1 and l2 must be at most 1 arm length"),
            (self.extend <= 1 and self.staccato_drop <= 0.5, "extend must be at most 1, staccato_drop at most 0.5"),
            (0 <= self.bounce <= 1, "bounce must be between 0 and 1"),
            (0.5 <= self.speed_limit <= 50, "speed_limit must be between 0.5 and 50 arm lengths per second"),
            (1 <= self.beat_acceleration <= 3, "beat_acceleration must be between 1 and 3"),
            (0.3 <= self.reach <= 0.99, "reach must be between 0.3 and 0.99 of the arm's length"),
            (0 <= self.elbow_min < self.elbow_max <= 170, "elbow limits must satisfy 0 <= elbow_min < elbow_max <= 170"),
            (self.swivel <= 90 and self.nod <= 45 and self.sway <= 30 and self.knee_bend <= 40,
             "angles too large: swivel <= 90, nod <= 45, sway <= 30, knee_bend <= 40 degrees"),
            (1 <= self.fps <= 240, "fps must be between 1 and 240"),
        ]
        for ok, msg in checks:
            if not ok:
                raise InputError(f"bad procedural parameter: {msg}")

    @property
    def weights(self) -> tuple[float, float, float, float]:
        return (self.w1, self.w2, self.w3, self.w4)


# Named looks. e1/e2 are the paper's two experiments (Fig. 10-12): a large and a small L1.
STYLES: dict[str, dict] = {
    "default": {},
    "e1": {"l1": 0.45, "l2": 0.3},
    "e2": {"l1": 0.1, "l2": 0.12},
    "calm": {"l1": 0.12, "l2": 0.1, "bounce": 0.3, "sweep_width": 0.6, "y_scale": 0.02, "nod": 4.0,
             "sway": 3.0, "beat_acceleration": 1.4, "nod_turn": 0.5, "sway_turn": 1.2, "w1": 0.5,
             "ideal_duration": 32.0, "extend": 0.6},
    "lively": {"l1": 0.35, "l2": 0.4, "bounce": 0.9, "sweep_width": 1.0, "y_scale": 0.05, "nod": 12.0,
               "sway": 8.0, "beat_acceleration": 2.6, "sway_turn": 0.4, "ideal_duration": 8.0},
}


def parameter_names() -> list[str]:
    return [f.name for f in fields(ProceduralConfig)]


def _coerce(name: str, value, where: str) -> float:
    if name not in parameter_names():
        raise InputError(f"{where}: unknown parameter {name!r}; known ones: {', '.join(parameter_names())}")
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise InputError(f"{where}: parameter {name} must be a number, got {value!r}")
    try:
        number = float(value)
    except ValueError:
        raise InputError(f"{where}: parameter {name} must be a number, got {value!r}") from None
    # is_integer, not number == int(number): int() of nan or inf raises (a config of "nan" or "inf"
    # would be an internal error); __post_init__ then refuses what is not finite.
    return int(number) if name == "max_segment_notes" and number.is_integer() else number


def from_style(style: str = "default", base: ProceduralConfig | None = None) -> ProceduralConfig:
    if style not in STYLES:
        raise InputError(f"unknown procedural style {style!r}; choose one of {', '.join(STYLES)}")
    return replace(base or ProceduralConfig(), **STYLES[style])


def load_config(path) -> ProceduralConfig:
    """A TOML file: an optional ``style = "name"`` and any parameter, e.g. ``l1 = 0.2``."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such config file; check the path") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{path}: not a valid TOML config ({exc}); write lines like 'l1 = 0.2'") from None
    style = data.pop("style", "default")
    if not isinstance(style, str):
        raise InputError(f"{path}: style must be a name in quotes, e.g. style = \"calm\"")
    if isinstance(data.get("procedural"), dict):  # allow a [procedural] table too
        data.update(data.pop("procedural"))
    values = {k: _coerce(k, v, str(path)) for k, v in data.items()}
    return replace(from_style(style), **values)


def parse_params(items, base: ProceduralConfig) -> ProceduralConfig:
    """Apply ``name=value`` overrides (the CLI's ``--param``)."""
    values = {}
    for item in items:
        name, sep, value = str(item).partition("=")
        if not sep:
            raise InputError(f"--param {item!r}: write it as name=value, e.g. --param l1=0.2")
        values[name.strip()] = _coerce(name.strip(), value.strip(), "--param")
    return replace(base, **values)


def make_config(*, style: str | None = None, config_path=None, params=(), fps: float | None = None) -> ProceduralConfig:
    """The CLI's order: a style, then a TOML file, then ``--param`` overrides, then ``--fps``."""
    if config_path is not None:
        if style is not None:
            raise InputError("give the style either with --style or inside the --config file, not both")
        cfg = load_config(config_path)
    else:
        cfg = from_style(style or "default")
    cfg = parse_params(params, cfg)
    return cfg if fps is None else replace(cfg, fps=fps)


def config_dict(cfg: ProceduralConfig) -> dict:
    return asdict(cfg)
