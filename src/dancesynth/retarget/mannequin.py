"""The built-in mannequin's body: a stylised low-poly dancer, generated here with numpy.

The body is a set of closed, smooth lofts, one per body part (torso, neck, head, each
arm, hand, thumb, leg and shoe, and a hair bun): a centre line through key points with an
elliptical (or slightly squarer, super-elliptic) cross-section whose half-widths follow the
keys, sampled in rings that come closer together near the joints, where the part bends,
and closed by rounded caps. Parts overlap where they meet, as an artist's mannequin's do,
so nothing tears when a joint turns: an arm's or a thigh's top is a ball centred on its
joint, which turns in place.

Skin weights are laid out along each loft: a ring belongs to the joint whose bone it lies
on and is blended, by a smoothstep a few centimetres wide, into the next joint's across
each elbow, knee, wrist and ankle; the torso's top and bottom also lean on the shoulders
and thighs. Colours are bands along the lofts (a top with short sleeves, trousers,
shoes, skin and hair); a band edge is a ring duplicated with each colour, so edges are
crisp, and normals are computed with the copies welded, so there is no shading seam.

Everything is in the rig's rest pose: T-pose, Y up, facing +Z, left towards +X, metres,
feet on y = 0, built on the joints of the skeleton it is given (``rigs.rig_skeleton
("mannequin")``), with lengths scaled by its hips' height.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from ..errors import InputError
from ..kinematics import fk
from ..types import Skeleton
from .character import Character, Mesh
from .rigs import rig_skeleton

_CANONICAL_HIPS_Y = 0.96   # the canonical body's hips height (rigs.BODY): lengths below are for it


def _linear(hex_srgb: str) -> np.ndarray:
    """A colour given as sRGB hex, in linear RGB 0..1 (what glTF vertex colours hold)."""
    c = np.array([int(hex_srgb[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


PALETTE = {
    "skin": _linear("#d9a07e"),
    "top": _linear("#e0484f"),       # a coral-red T-shirt
    "trousers": _linear("#27304d"),  # navy
    "shoes": _linear("#f0ede6"),     # off-white dance sneakers
    "hair": _linear("#3a2418"),      # dark brown
}

_BONES = ("hips", "spine", "chest", "upperChest", "neck", "head") + tuple(
    side + part for side in ("left", "right") for part in
    ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _ramp(v: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """0 below ``lo``, 1 above ``hi``, smooth in between (``hi < lo`` ramps down)."""
    return _smoothstep((v - lo) / (hi - lo))


@dataclass(frozen=True)
class _Loft:
    """One closed body part: a tube along a smooth centre line with rounded ends.

    ``keys`` (K, 3) are points of the centre line (world) and ``radii`` (K, 2) the
    cross-section's half-widths there, along ``up`` (made perpendicular to the line) and
    across it. ``joint`` owns the part's start; each ``(point, joint, half_width)`` of
    ``blends`` takes over where the line passes ``point``, blended over ``half_width``
    either side. ``colours`` starts with the first band's colour name, then ``(point, name)``
    edges. ``caps``: lengths of the rounded start and end. ``exponent`` 2 is an ellipse,
    more is squarer. ``step``/``fine``: ring spacing along the part and near its blends.
    Lengths other than ``keys`` are canonical metres, scaled to the rig when built.
    """

    keys: np.ndarray
    radii: np.ndarray                # (K, 2), or a list of pairs
    up: tuple[float, float, float]
    joint: int
    blends: tuple = ()
    colours: tuple = ("skin",)
    caps: tuple[float, float] = (0.02, 0.02)
    sides: int = 16
    exponent: float = 2.0
    step: float = 0.04
    fine: float = 0.018
    cap_rings: int = 3


@dataclass
class _Part:
    positions: np.ndarray   # (V, 3)
    triangles: np.ndarray   # (T, 3) indices into positions
    weld: np.ndarray        # (V,) the vertex each one shares its normal with (colour seams are duplicated)
    weights: np.ndarray     # (V, J) dense skin weights
    colours: np.ndarray     # (V, 3)


def _build(loft: _Loft, n_joints: int, scale: float) -> _Part:
    """The vertices, triangles, weights and colours of one loft, its lengths multiplied by ``scale``."""
    keys = np.asarray(loft.keys, dtype=np.float64)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(keys, axis=0), axis=1))])
    centre = PchipInterpolator(chord, keys)          # monotone cubic: smooth, never overshoots a key
    radius = PchipInterpolator(chord, scale * np.asarray(loft.radii, dtype=np.float64))
    length = chord[-1]

    def along(point) -> float:
        """Where the centre line passes closest to ``point`` (metres along it)."""
        s = np.linspace(0.0, length, 400)
        return float(s[np.argmin(np.linalg.norm(centre(s) - np.asarray(point), axis=1))])

    blends = sorted((along(p), j, scale * hw) for p, j, hw in loft.blends)
    edges = [along(p) for p, _ in loft.colours[1:]]
    s = _stations(length, [b[0] for b in blends], edges, scale * loft.step, scale * loft.fine)

    # The rounded caps: rings shrinking as cos(theta) while they move on by sin(theta), then a pole.
    theta = np.arange(1, loft.cap_rings + 1) / (loft.cap_rings + 1) * (np.pi / 2)
    start_l, end_l = scale * np.asarray(loft.caps)
    ring_s = np.concatenate([-start_l * np.sin(theta[::-1]), s, length + end_l * np.sin(theta)])
    shrink = np.concatenate([np.cos(theta[::-1]), np.ones(len(s)), np.cos(theta)])
    inside = np.clip(ring_s, 0.0, length)
    t = _unit(centre.derivative()(inside))
    c = centre(inside) + t * (ring_s - inside)[:, None]
    r = radius(inside) * shrink[:, None]
    up = np.asarray(loft.up, dtype=np.float64)
    u = _unit(up - np.sum(up * t, axis=1, keepdims=True) * t)
    v = np.cross(t, u)                                # u x v = t: counter-clockwise seen from outside

    phi = 2 * np.pi * np.arange(loft.sides) / loft.sides
    cu, sv = (np.sign(f) * np.abs(f) ** (2.0 / loft.exponent) for f in (np.cos(phi), np.sin(phi)))
    rings = c[:, None] + r[:, None, :1] * cu[:, None] * u[:, None] + r[:, None, 1:] * sv[:, None] * v[:, None]
    gap = 1.0 - np.sin(theta[-1])                     # from the last cap ring on to the pole
    poles = np.stack([c[0] - t[0] * start_l * gap, c[-1] + t[-1] * end_l * gap])
    triangles, weld = _tube(len(ring_s), loft.sides, twin=np.diff(ring_s) == 0.0)

    band = np.searchsorted(edges, ring_s, side="right")
    band[:-1][np.diff(ring_s) == 0.0] -= 1            # an edge's first ring keeps the band before it
    names = [loft.colours[0]] + [name for _, name in loft.colours[1:]]
    ring_colours = np.array([PALETTE[names[b]] for b in band])
    ring_weights = _ring_weights(ring_s, loft.joint, blends, n_joints)

    def per_vertex(per_ring: np.ndarray) -> np.ndarray:
        return np.concatenate([np.repeat(per_ring, loft.sides, axis=0), per_ring[[0, -1]]])  # poles last

    return _Part(np.concatenate([rings.reshape(-1, 3), poles]), triangles, weld, per_vertex(ring_weights),
                 per_vertex(ring_colours))


def _tube(n_rings: int, n: int, twin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles joining ``n_rings`` rings of ``n`` vertices (then a pole at each end), and each
    vertex's weld: ring k + 1 that ``twin[k]`` marks repeats ring k (a colour edge), so the two
    are not joined and the repeat shares its twin's normals."""
    i = np.arange(n)
    k = np.flatnonzero(~twin)[:, None]                # ring k joins ring k + 1
    a, b, c, d = k * n + i, k * n + (i + 1) % n, (k + 1) * n + (i + 1) % n, (k + 1) * n + i
    quads = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=1).reshape(-1, 3)
    first, last = n_rings * n, n_rings * n + 1
    fans = [np.stack([np.full(n, first), (i + 1) % n, i], -1),
            np.stack([(n_rings - 1) * n + i, (n_rings - 1) * n + (i + 1) % n, np.full(n, last)], -1)]
    repeat = np.concatenate([[False], twin])
    owner = np.flatnonzero(~repeat)[np.arange(n_rings) - np.cumsum(repeat)]
    weld = np.concatenate([(owner[:, None] * n + i).reshape(-1), [first, last]])
    return np.concatenate([quads] + fans), weld


def _stations(length: float, blends: list[float], edges: list[float], step: float, fine: float) -> np.ndarray:
    """Where the rings go along a part: every ``step``, every ``fine`` within a few cm of a blend
    (where the part bends), and twice at each colour edge."""
    s = [np.linspace(0.0, length, max(int(np.ceil(length / step)), 1) + 1)]
    for b in blends:
        zone = 2.5 * fine
        s.append(np.clip(b + np.arange(-zone, zone + 1e-9, fine), 0.0, length))
    s = np.unique(np.concatenate(s))
    # Drop rings crowding a kept one (keeping the ends), or an edge.
    keep = [s[0]]
    for x in s[1:-1]:
        if x - keep[-1] > 0.55 * fine and length - x > 0.55 * fine:
            keep.append(x)
    keep.append(s[-1])
    s = np.array(keep)
    for e in edges:
        s = s[np.abs(s - e) > 0.4 * fine]
    return np.sort(np.concatenate([s, edges, edges]))


def _ring_weights(s: np.ndarray, joint: int, blends: list, n_joints: int) -> np.ndarray:
    """(R, J) skin weights of rings at ``s``: ``joint`` until each blend hands over to the next joint."""
    w = np.zeros((len(s), n_joints))
    w[:, joint] = 1.0
    for at, j, half in blends:
        t = _smoothstep((s - at + half) / (2 * half))[:, None]
        w *= 1.0 - t
        w[:, j] += t[:, 0]
    return w


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _lean(weights: np.ndarray, amount: np.ndarray, joint: int) -> np.ndarray:
    """Weights moved towards ``joint`` by ``amount`` (V,) of each vertex's total."""
    out = weights * (1.0 - amount)[:, None]
    out[:, joint] += amount
    return out


def mannequin_mesh(skeleton: Skeleton, bones: dict[str, int]) -> Mesh:
    """The dancer's body skinned to ``skeleton`` in its rest pose (identity rotations, root at its offset).

    ``bones`` maps the VRM humanoid bone names to joints and must name all 22 of the
    mannequin rig (``rigs.rig_skeleton("mannequin")``).
    """
    missing = [b for b in _BONES if b not in bones]
    if missing:
        raise InputError(f"the mannequin body needs the humanoid bones {', '.join(missing)}; "
                         "build it on rigs.rig_skeleton('mannequin')")
    rest = np.tile([0.0, 0.0, 0.0, 1.0], (skeleton.n_joints, 1))
    _, world = fk(rest, skeleton.offsets[0], skeleton.offsets, skeleton.parents)
    if not world[bones["hips"], 1] > 0:
        raise InputError("the mannequin body needs a skeleton standing on y = 0 with its hips above it")
    rig = _Rig(world, bones, world[bones["hips"], 1] / _CANONICAL_HIPS_Y)
    lofts = _core(rig) + _limbs(rig, "left") + _limbs(rig, "right")
    parts = [_build(loft, skeleton.n_joints, rig.scale) for loft in lofts]
    _lean_torso(parts[0], rig)
    return _assemble(parts)


@dataclass(frozen=True)
class _Rig:
    """The rest pose the body is built on: joint positions (world), humanoid bones, and the size of
    this body against the canonical one, by which every length below (canonical metres) is scaled."""

    world: np.ndarray
    bones: dict[str, int]
    scale: float

    def at(self, bone: str, dx=0.0, dy=0.0, dz=0.0, mirror=1.0) -> np.ndarray:
        """A point (dx, dy, dz) from a joint; ``mirror`` -1 flips dx for the right side."""
        return self.world[self.bones[bone]] + self.scale * np.array([mirror * dx, dy, dz])

    def joint(self, bone: str) -> int:
        return self.bones[bone]


def _core(rig: _Rig) -> list[_Loft]:
    """The torso (first), neck, head and hair bun."""
    at, j = rig.at, rig.joint
    torso = np.array([  # height above the hips, half width, half depth, forward shift
        (-0.110, 0.118, 0.090, 0.000), (-0.040, 0.165, 0.108, -0.008), (0.040, 0.154, 0.100, -0.006),
        (0.120, 0.132, 0.088, 0.000), (0.210, 0.142, 0.096, 0.008), (0.300, 0.162, 0.106, 0.014),
        (0.380, 0.178, 0.098, 0.004), (0.440, 0.188, 0.085, -0.008), (0.480, 0.172, 0.070, -0.014)])
    spine_z = np.interp(torso[:, 0], [0.0, 0.35, 0.50], [0.0, -0.02, -0.025])   # the spine leans back a little
    torso_keys = np.stack([at("hips", dy=h, dz=z) for h, z in zip(torso[:, 0], spine_z + torso[:, 3])])
    return [
        _Loft(torso_keys, torso[:, 1:3], (1.0, 0.0, 0.0), j("hips"),
              blends=((at("spine"), j("spine"), 0.05), (at("chest"), j("chest"), 0.05),
                      (at("upperChest"), j("upperChest"), 0.05)),
              colours=("trousers", (at("hips", dy=0.05), "top")), caps=(0.04, 0.04),
              sides=24, exponent=2.4, step=0.045, fine=0.03, cap_rings=4),
        _Loft(np.stack([at("neck", dy=-0.07, dz=-0.005), at("neck"), at("head", dy=0.05)]),
              [(0.056, 0.060), (0.052, 0.054), (0.050, 0.052)], (1.0, 0.0, 0.0), j("upperChest"),
              blends=((at("neck"), j("neck"), 0.03), (at("head"), j("head"), 0.03)),
              sides=12, fine=0.02, cap_rings=2),
        # An egg, wider above than at the chin, tilted back so the hairline is higher at the front.
        _Loft(np.stack([at("head", dy=0.005, dz=0.022), at("head", dy=0.05, dz=0.014),
                        at("head", dy=0.095, dz=0.005), at("head", dy=0.135, dz=-0.005)]),
              [(0.068, 0.078), (0.080, 0.094), (0.085, 0.101), (0.082, 0.098)], (1.0, 0.0, 0.0), j("head"),
              colours=("skin", (at("head", dy=0.1), "hair")), caps=(0.04, 0.065),
              sides=20, step=0.025, cap_rings=5),
        # A bun at the back of the head: reads as a dancer, and shows which way the head faces.
        _Loft(np.stack([at("head", dy=0.13, dz=-0.095), at("head", dy=0.14, dz=-0.115)]),
              [(0.040, 0.040), (0.040, 0.040)], (1.0, 0.0, 0.0), j("head"), colours=("hair",),
              caps=(0.035, 0.035), sides=10, step=0.02),
    ]


def _limbs(rig: _Rig, side: str) -> list[_Loft]:
    """One side's arm, hand, thumb, leg and shoe."""
    m = 1.0 if side == "left" else -1.0               # mirrors x for the right side
    j = rig.joint
    upper, lower, hand, shoulder = (side + p for p in ("UpperArm", "LowerArm", "Hand", "Shoulder"))
    thigh, shin, foot, toes = (side + p for p in ("UpperLeg", "LowerLeg", "Foot", "Toes"))

    def at(bone, dx=0.0, dy=0.0, dz=0.0):
        return rig.at(bone, dx, dy, dz, mirror=m)

    arm = np.array([  # from the shoulder ball along the arm: distance, half height, half depth
        (0.0, 0.044, 0.046), (0.06, 0.046, 0.048), (0.15, 0.045, 0.046), (0.23, 0.039, 0.040),
        (0.275, 0.036, 0.037), (0.32, 0.038, 0.041), (0.41, 0.033, 0.036), (0.50, 0.026, 0.031),
        (0.52, 0.025, 0.030)])
    leg = np.array([  # from the hip joint down the leg: offset (x, y, z), half width, half depth
        (0.0, 0.0, 0.0, 0.078, 0.082), (0.002, -0.11, 0.0, 0.082, 0.086), (0.004, -0.25, 0.005, 0.066, 0.070),
        (0.005, -0.37, 0.01, 0.050, 0.052), (0.005, -0.41, 0.012, 0.047, 0.050), (0.006, -0.47, 0.0, 0.049, 0.055),
        (0.008, -0.57, -0.012, 0.046, 0.052), (0.009, -0.69, -0.015, 0.036, 0.040),
        (0.01, -0.79, -0.018, 0.030, 0.034), (0.01, -0.83, -0.02, 0.030, 0.033)])
    shoe = np.array([  # from the heel along the foot: forward, half width, half height (the sole on the floor)
        (-0.055, 0.036, 0.044), (-0.015, 0.042, 0.057), (0.035, 0.045, 0.047), (0.095, 0.047, 0.035),
        (0.145, 0.043, 0.029), (0.180, 0.037, 0.025)])
    over_floor = np.array([1.0, 0.0, 1.0])
    return [
        # Upper arm and forearm, from a ball at the shoulder that turns in place under the torso's shoulder.
        _Loft(np.stack([at(upper, dx=x) for x in arm[:, 0]]), arm[:, 1:], (0.0, 1.0, 0.0), j(shoulder),
              blends=((at(upper, dx=0.03), j(upper), 0.04), (at(lower), j(lower), 0.045), (at(hand), j(hand), 0.02)),
              colours=("top", (at(upper, dx=0.13), "skin")), caps=(0.05, 0.02)),
        # A mitten: flat, wider across the palm than at the wrist.
        _Loft(np.stack([at(hand, dx=x) for x in (0.0, 0.03, 0.09, 0.13, 0.155)]),
              [(0.020, 0.027), (0.023, 0.036), (0.022, 0.043), (0.019, 0.040), (0.016, 0.034)],
              (0.0, 1.0, 0.0), j(lower), blends=((at(hand), j(hand), 0.015),),
              caps=(0.015, 0.022), sides=10, exponent=2.5, step=0.03),
        _Loft(np.stack([at(hand, dx=0.03, dy=-0.008, dz=0.025), at(hand, dx=0.075, dy=-0.016, dz=0.055)]),
              [(0.012, 0.012), (0.010, 0.010)], (0.0, 1.0, 0.0), j(hand),
              caps=(0.01, 0.011), sides=6, step=0.03, cap_rings=2),
        # Thigh, knee, calf and ankle, from a ball at the hip inside the pelvis.
        _Loft(np.stack([at(thigh, *d) for d in leg[:, :3]]), leg[:, 3:], (1.0, 0.0, 0.0), j(thigh),
              blends=((at(shin), j(shin), 0.05), (at(foot), j(foot), 0.03)),
              colours=("trousers",), caps=(0.06, 0.03), step=0.06, fine=0.02),
        _Loft(np.stack([at(foot, dz=z) * over_floor + [0.0, rig.scale * h, 0.0] for z, _, h in shoe]),
              shoe[:, 1:], (1.0, 0.0, 0.0), j(foot), blends=((at(toes), j(toes), 0.03),),
              colours=("shoes",), caps=(0.02, 0.025), exponent=3.0, step=0.035),
    ]


def _lean_torso(torso: _Part, rig: _Rig) -> None:
    """The torso's shoulders follow the shoulder joints (a shrug lifts them), and the seat of the
    trousers follows the thighs a little, so the torso's edges move with the limbs beside them."""
    p = torso.positions
    hips, neck = rig.at("hips"), rig.at("neck")
    x = (p[:, 0] - hips[0]) / rig.scale
    for side, sign in (("left", 1.0), ("right", -1.0)):
        out = np.maximum(sign * x, 0.0)
        shoulder = _ramp(out, 0.08, 0.16) * _ramp((p[:, 1] - neck[1]) / rig.scale, -0.18, -0.08)
        torso.weights = _lean(torso.weights, shoulder, rig.joint(side + "Shoulder"))
        seat = 0.35 * _ramp(out, 0.02, 0.10) * _ramp((p[:, 1] - hips[1]) / rig.scale, -0.03, -0.12)
        torso.weights = _lean(torso.weights, seat, rig.joint(side + "UpperLeg"))


def _assemble(parts: list[_Part]) -> Mesh:
    """One mesh of all the parts: smooth normals, and each vertex's four strongest weights summing to 1."""
    offsets = np.cumsum([0] + [len(p.positions) for p in parts])
    positions = np.concatenate([p.positions for p in parts])
    triangles = np.concatenate([p.triangles + o for p, o in zip(parts, offsets)])
    weld = np.concatenate([p.weld + o for p, o in zip(parts, offsets)])
    # Area-weighted face normals summed at each welded vertex.
    tri = positions[triangles]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    at = weld[triangles].reshape(-1)
    summed = np.stack([np.bincount(at, np.repeat(face[:, k], 3), len(positions)) for k in range(3)], axis=1)
    normals = _unit(summed[weld])

    dense = np.concatenate([p.weights for p in parts])
    joints = np.argsort(-dense, axis=1, kind="stable")[:, :4]
    weights = np.take_along_axis(dense, joints, axis=1)
    weights[weights < 1e-4] = 0.0                     # a trace of a joint is not worth a slot
    weights /= weights.sum(axis=1, keepdims=True)
    joints[weights == 0.0] = 0                        # unused slots name joint 0 (glTF asks for that)
    return Mesh(positions=positions.astype(np.float32), normals=normals.astype(np.float32),
                indices=triangles.astype(np.uint32), joints=joints.astype(np.uint16),
                weights=weights.astype(np.float32),
                colours=np.concatenate([p.colours for p in parts]).astype(np.float32))


@functools.lru_cache(maxsize=1)
def mannequin_character() -> Character:
    """The built-in mannequin: the canonical rig in its T-pose, with its dancer's body."""
    skeleton, bones = rig_skeleton("mannequin")
    rest_rot = np.tile([0.0, 0.0, 0.0, 1.0], (skeleton.n_joints, 1))
    return Character(name="mannequin", skeleton=skeleton, bones=bones, rest_rot=rest_rot,
                     rest_root=skeleton.offsets[0].copy(), mesh=mannequin_mesh(skeleton, bones), kind="builtin")
