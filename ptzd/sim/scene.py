"""`synthetic[:SEED]`: a procedural wide scene of people walking on a plaza, with exact truth.

A static camera `camera_height` metres above flat ground looks at a paved plaza (grass at the
sides) with buildings behind it, and trees, lamp poles, advertising pillars, benches and a
hedge standing on it. People walk across it with an articulated gait: each has its own
height, build and clothing (skin, hair, shirt, sleeves, trousers, shoes), speed, path and
sometimes a pause. Perspective is exact for the ground plane: a point at depth Z metres is
drawn at `f / Z` pixels per metre, so people grow as they approach (40 to 200 px tall at the
default size) and shrink as they recede. Everything is drawn far to near, so poles, pillars
and nearer people hide those behind them. The frame then gets a slow lighting change and
mild sensor noise.

Every random choice comes from the seed, and frame `i` is a pure function of (seed, i):
frames can be read in any order and are identical across runs.

Ground truth, per person and frame: the box tightly enclosing the person's whole drawn body
(the exact pixel bounding box of the figure, including parts hidden by occluders or other
people), clipped to the frame; frames in which the person is entirely outside the frame are
left out. Fully occluded frames ARE included, and each track carries a `visibility` map: the
fraction of the body's pixels that are visible in the frame (0 = fully hidden).

A thermal variant (`thermal=True`, `synthetic-thermal:SEED`) draws the same scene as a
thermal camera sees it: warm people on cool, cluttered ground, with hot non-human objects
(lamp heads, vents, a warm car bonnet); one grey channel, replicated to BGR by the source.

Write a scene to a video and ground-truth file (used by benchmarks)::

    python -m ptzd.sim.scene --seed 3 --frames 300 --out DIR   # DIR/scene.avi, DIR/gt.json
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from pydantic import Field, model_validator

from ptzd.errors import UsageError
from ptzd.schema import StrictModel
from ptzd.sim.groundtruth import Box, GroundTruth, save_ground_truth
from ptzd.sim.sources import wrap_index

if TYPE_CHECKING:
    from numpy.typing import NDArray

    U8 = NDArray[np.uint8]
    F32 = NDArray[np.float32]

_SHIFT = 4  # cv2 drawing with 4 fractional bits: sub-pixel placement, smooth motion
_ONE = 1 << _SHIFT

# figure labels: what each pixel of a drawn person is (0 = not the person)
_SKIN, _HAIR, _SHIRT, _SHIRT_BACK, _TROUSERS, _TROUSERS_BACK, _SHOES = 1, 2, 3, 4, 5, 6, 7
_LABELS = 8


class SceneParams(StrictModel):
    """What the procedural scene looks like; every field has a bounded, documented default."""

    width: int = Field(default=1280, ge=320, le=3840)
    height: int = Field(default=720, ge=240, le=2160)
    fps: float = Field(default=25.0, gt=0.0, le=120.0)
    frame_count: int = Field(default=1500, ge=1, le=1_000_000)
    # horizontal FOV of the scene's own pinhole (perspective of the ground), degrees
    hfov: float = Field(default=60.0, ge=20.0, le=120.0)
    camera_height: float = Field(default=4.5, ge=1.5, le=30.0)  # metres above the ground
    horizon: float = Field(default=0.3, ge=0.05, le=0.6)  # horizon row, fraction of height
    people_per_minute: float = Field(default=14.0, ge=0.0, le=200.0)  # unscripted walkers
    noise_sigma: float = Field(default=2.0, ge=0.0, le=30.0)  # sensor noise, grey levels
    lighting_amplitude: float = Field(default=0.08, ge=0.0, le=0.5)  # slow gain change
    thermal: bool = False

    @model_validator(mode="after")
    def _check_depth(self) -> SceneParams:
        if self.focal * self.camera_height / (self.height * (1 - self.horizon)) > _FAR_Z / 2:
            raise ValueError("the ground is too far away: raise the horizon or lower the camera")
        return self

    @property
    def focal(self) -> float:
        return (self.width / 2) / math.tan(math.radians(self.hfov) / 2)


_FAR_Z = 44.0  # metres: people walk no farther than this
_BUILDING_Z = 62.0  # metres: the building fronts


@dataclass(frozen=True)
class GroundCamera:
    """The scene camera: optical axis level with the ground, horizon at row `horizon_y`."""

    f: float
    cx: float
    horizon_y: float
    height_m: float
    width: int
    height: int

    def image_x(self, X: float, Z: float) -> float:
        return self.cx + self.f * X / Z

    def image_y(self, Y_above_ground: float, Z: float) -> float:
        return self.horizon_y + self.f * (self.height_m - Y_above_ground) / Z

    def half_width_m(self, Z: float) -> float:
        """Half the ground width visible at depth Z."""
        return Z * self.cx / self.f

    @property
    def near_z(self) -> float:
        """Depth whose ground point is the bottom image row."""
        return self.f * self.height_m / (self.height - self.horizon_y)


@dataclass(frozen=True)
class Occluder:
    """A static object standing on the ground, pre-drawn: its pixels, mask and depth."""

    kind: str
    z: float
    x0: int
    y0: int
    image: U8  # h x w x channels
    mask: NDArray[np.bool_]

    @property
    def box(self) -> tuple[int, int, int, int]:
        return self.x0, self.y0, self.x0 + self.mask.shape[1], self.y0 + self.mask.shape[0]


@dataclass(frozen=True)
class Walker:
    """One person: looks and a path on the ground walked at constant speed (maybe a pause)."""

    id: int
    height_m: float
    build: float  # width factor
    palette: U8  # _LABELS x 3 BGR colours by label
    long_sleeves: bool
    path: NDArray[np.float64]  # n x 2 waypoints (X, Z), metres
    speed: float  # metres per second
    t0: float  # seconds: when it is at path[0]
    cycle_m: float  # metres walked per gait cycle (two steps)
    pause_at: float  # metres along the path where it stands still (inf = never)
    pause_s: float

    @cached_property
    def _cumulative(self) -> NDArray[np.float64]:
        steps = np.linalg.norm(np.diff(self.path, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    @property
    def length(self) -> float:
        return float(self._cumulative[-1])

    @property
    def t1(self) -> float:
        return (
            self.t0
            + self.length / self.speed
            + (self.pause_s if self.pause_at < self.length else 0)
        )

    def state(self, t: float) -> tuple[float, float, float, float, float] | None:
        """(X, Z, dX, dZ, distance walked) at time t, None outside its walk."""
        if t < self.t0 or t > self.t1:
            return None
        walked = self.speed * (t - self.t0)
        if walked > self.pause_at:
            walked = max(self.pause_at, walked - self.speed * self.pause_s)
        cum = self._cumulative
        seg = min(int(np.searchsorted(cum, walked, side="right")) - 1, len(cum) - 2)
        seg = max(seg, 0)
        a, b = self.path[seg], self.path[seg + 1]
        span = cum[seg + 1] - cum[seg]
        u = 0.0 if span <= 0 else (walked - cum[seg]) / span
        X, Z = a + (b - a) * u
        dX, dZ = (b - a) / max(span, 1e-9)
        return float(X), float(Z), float(dX), float(dZ), walked

    def moving(self, t: float) -> bool:
        start = self.t0 + self.pause_at / self.speed
        return not start <= t < start + self.pause_s


@dataclass(frozen=True)
class Sprite:
    """A person drawn for one frame: labels (0 = not the person) placed at (x0, y0)."""

    walker_id: int
    z: float
    x0: int
    y0: int
    labels: U8

    @property
    def box(self) -> tuple[int, int, int, int]:
        return self.x0, self.y0, self.x0 + self.labels.shape[1], self.y0 + self.labels.shape[0]


class Scene:
    """The procedural scene of one seed: `render(i)` draws frame i; `ground_truth()` says
    where everybody is. Nothing heavy happens until first use."""

    def __init__(self, seed: int, params: SceneParams | None = None) -> None:
        self.seed = seed
        self.params = params if params is not None else SceneParams()
        p = self.params
        self.camera = GroundCamera(
            p.focal, p.width / 2, p.height * p.horizon, p.camera_height, p.width, p.height
        )

    @property
    def size(self) -> tuple[int, int]:
        return self.params.width, self.params.height

    @property
    def fps(self) -> float:
        return self.params.fps

    @property
    def frame_count(self) -> int:
        return self.params.frame_count

    # --- layout (pure functions of the seed) ------------------------------------------

    @cached_property
    def occluders(self) -> list[Occluder]:
        """Static objects, far to near."""
        return _place_occluders(self.camera, self.seed, thermal=self.params.thermal)

    @cached_property
    def walkers(self) -> list[Walker]:
        return _plan_walkers(self.camera, self.params, self.seed, self.occluders)

    @cached_property
    def background(self) -> U8:
        """Sky, buildings, ground and the static objects (drawn once)."""
        image = _background(self.camera, self.seed, thermal=self.params.thermal)
        for occ in self.occluders:
            _paste(image, occ.image, occ.mask, occ.x0, occ.y0)
        return image

    @cached_property
    def _by_id(self) -> dict[int, Walker]:
        return {walker.id: walker for walker in self.walkers}

    @cached_property
    def _walk_times(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return (
            np.array([w.t0 for w in self.walkers], np.float64),
            np.array([w.t1 for w in self.walkers], np.float64),
        )

    def sprites(self, index: int) -> list[Sprite]:
        """Every person present at frame `index`, far to near."""
        t = index / self.params.fps
        t0, t1 = self._walk_times
        out: list[Sprite] = []
        for k in np.flatnonzero((t0 <= t) & (t <= t1)):
            walker = self.walkers[k]
            sprite = _draw_walker(self.camera, walker, t)
            if sprite is not None:
                out.append(sprite)
        out.sort(key=lambda s: -s.z)
        return out

    # --- rendering ----------------------------------------------------------------------

    def render(self, index: int) -> U8:
        """Frame `index` (H x W x 3 BGR, or H x W grey when thermal)."""
        frame = self.background.copy()
        occluders = self.occluders
        for sprite in self.sprites(index):
            palette = self._by_id[sprite.walker_id].palette
            colours = (
                palette[sprite.labels] if not self.params.thermal else palette[sprite.labels, 0]
            )
            _paste(frame, colours, sprite.labels > 0, sprite.x0, sprite.y0)
            # static objects in front of this person cover it again, far to near
            for occ in occluders:
                if occ.z < sprite.z and _overlap(occ.box, sprite.box) is not None:
                    _paste_within(frame, occ, sprite.box)
        return self._sensor(frame, index)

    @cached_property
    def _noise(self) -> tuple[U8, int]:
        """A bank of noise bigger than the frame, stored as uint8 around `offset`; each frame
        uses a window of it at its own offset."""
        p = self.params
        rng = np.random.default_rng([self.seed, 7])
        shape: tuple[int, ...] = (p.height + 64, p.width + 64)
        if not p.thermal:
            shape = (*shape, 3)
        offset = max(1, math.ceil(4 * p.noise_sigma))
        noise = rng.normal(0.0, p.noise_sigma, shape).astype(np.float32)
        bank = np.clip(np.rint(noise) + offset, 0, 2 * offset).astype(np.uint8)
        return bank, offset

    def lighting(self, index: int) -> float:
        """Global gain of frame `index`: two slow waves (clouds, sun) around 1."""
        t = index / self.params.fps
        rng = np.random.default_rng([self.seed, 11])
        phase1, phase2 = rng.uniform(0, 2 * math.pi, 2)
        a = self.params.lighting_amplitude
        return (
            1.0
            + a * (0.7 * math.sin(2 * math.pi * t / 37.0 + phase1))
            + a * 0.3 * math.sin(2 * math.pi * t / 11.0 + phase2)
        )

    def _sensor(self, frame: U8, index: int) -> U8:
        """Lighting gain and sensor noise in one pass: frame * gain + noise (saturated)."""
        gain = self.lighting(index)
        if self.params.noise_sigma <= 0:
            return np.asarray(cv2.convertScaleAbs(frame, alpha=gain), np.uint8)
        bank, offset = self._noise
        # a per-frame window: deterministic in the index, different from frame to frame
        dy = (index * 37 + self.seed * 11) % 64
        dx = (index * 53 + self.seed * 7) % 64
        h, w = frame.shape[:2]
        noise = bank[dy : dy + h, dx : dx + w]
        cv2.addWeighted(frame, gain, noise, 1.0, -float(offset), dst=frame)
        return frame

    # --- ground truth -------------------------------------------------------------------

    def frame_truth(self, index: int) -> dict[int, tuple[Box, float]]:
        """`{walker id: (box, visible fraction)}` at frame `index` (clipped to the frame)."""
        W, H = self.size
        sprites = self.sprites(index)
        out: dict[int, tuple[Box, float]] = {}
        for i, sprite in enumerate(sprites):
            mask = sprite.labels > 0
            total = int(mask.sum())
            if total == 0:
                continue
            # the tight box of the body's pixels that fall inside the frame
            sx0, sy0 = sprite.x0, sprite.y0
            in_frame = mask.copy()
            in_frame[: max(0, -sy0), :] = False
            in_frame[:, : max(0, -sx0)] = False
            in_frame[max(0, H - sy0) :, :] = False
            in_frame[:, max(0, W - sx0) :] = False
            if not in_frame.any():
                continue
            x, y, w, h = cv2.boundingRect(in_frame.astype(np.uint8))
            hidden = np.zeros_like(mask)
            for nearer in sprites[i + 1 :]:
                _or_within(hidden, sprite.box, nearer.labels > 0, nearer.box)
            for occ in self.occluders:
                if occ.z < sprite.z:
                    _or_within(hidden, sprite.box, occ.mask, occ.box)
            visible = in_frame & ~hidden
            box = (float(sx0 + x), float(sy0 + y), float(w), float(h))
            out[sprite.walker_id] = (box, int(visible.sum()) / total)
        return out

    def ground_truth(self) -> GroundTruth:
        tracks: dict[int, dict[int, Box]] = {}
        visibility: dict[int, dict[int, float]] = {}
        for index in range(self.frame_count):
            for walker_id, (box, visible) in self.frame_truth(index).items():
                tracks.setdefault(walker_id, {})[index] = box
                visibility.setdefault(walker_id, {})[index] = round(visible, 4)
        return GroundTruth(self.size, self.fps, tracks, visibility)


@lru_cache(maxsize=8)
def _scene_truth(seed: int, params: SceneParams) -> GroundTruth:
    """Ground truth of a scene, shared by every source of the same scene in this process."""
    return Scene(seed, params).ground_truth()


class SceneSource:
    """`WideSource` of a `Scene`: BGR frames, ground truth computed on first use."""

    def __init__(
        self,
        seed: int = 0,
        *,
        loop: bool = False,
        thermal: bool = False,
        params: SceneParams | None = None,
    ) -> None:
        base = params if params is not None else SceneParams()
        if thermal != base.thermal:
            base = base.model_copy(update={"thermal": thermal})
        self.scene = Scene(seed, base)
        self.loop = loop
        self._attached: GroundTruth | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.scene.size

    @property
    def fps(self) -> float:
        return self.scene.fps

    @property
    def frame_count(self) -> int:
        return self.scene.frame_count

    @property
    def ground_truth(self) -> GroundTruth:
        if self._attached is not None:
            return self._attached
        return self._computed_truth

    @cached_property
    def _computed_truth(self) -> GroundTruth:
        return _scene_truth(self.scene.seed, self.scene.params)

    def attach_ground_truth(self, gt: GroundTruth) -> None:
        """Use a ground truth loaded from a file instead of the computed one."""
        self._attached = gt

    def read(self, index: int) -> U8:
        frame = self.scene.render(wrap_index(index, self.frame_count, loop=self.loop))
        if frame.ndim == 2:
            return np.asarray(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR), np.uint8)
        return frame


# --- drawing helpers --------------------------------------------------------------------


def _overlap(
    a: tuple[int, int, int, int], b: tuple[int, int, int, int]
) -> tuple[int, int, int, int] | None:
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def _paste(frame: U8, image: U8, mask: NDArray[np.bool_], x0: int, y0: int) -> None:
    """Copy `image` where `mask` into `frame` at (x0, y0), clipped to the frame."""
    H, W = frame.shape[:2]
    h, w = mask.shape
    fx0, fy0, fx1, fy1 = max(x0, 0), max(y0, 0), min(x0 + w, W), min(y0 + h, H)
    if fx1 <= fx0 or fy1 <= fy0:
        return
    src = image[fy0 - y0 : fy1 - y0, fx0 - x0 : fx1 - x0]
    where = mask[fy0 - y0 : fy1 - y0, fx0 - x0 : fx1 - x0]
    if frame.ndim == 3:
        where = where[:, :, None]
    np.copyto(frame[fy0:fy1, fx0:fx1], src, where=where)


def _paste_within(frame: U8, occ: Occluder, region: tuple[int, int, int, int]) -> None:
    """Paste the part of `occ` that lies inside `region` (x0, y0, x1, y1)."""
    box = _overlap(occ.box, region)
    if box is None:
        return
    x0, y0, x1, y1 = box
    sy, sx = slice(y0 - occ.y0, y1 - occ.y0), slice(x0 - occ.x0, x1 - occ.x0)
    _paste(frame, occ.image[sy, sx], occ.mask[sy, sx], x0, y0)


def _or_within(
    hidden: NDArray[np.bool_],
    box: tuple[int, int, int, int],
    mask: NDArray[np.bool_],
    mask_box: tuple[int, int, int, int],
) -> None:
    """hidden (placed at `box`) |= mask (placed at `mask_box`) where they overlap."""
    inter = _overlap(box, mask_box)
    if inter is None:
        return
    x0, y0, x1, y1 = inter
    hidden[y0 - box[1] : y1 - box[1], x0 - box[0] : x1 - box[0]] |= mask[
        y0 - mask_box[1] : y1 - mask_box[1], x0 - mask_box[0] : x1 - mask_box[0]
    ]


def _pt(x: float, y: float) -> tuple[int, int]:
    return round(x * _ONE), round(y * _ONE)


def _limb(
    img: U8, a: tuple[float, float], b: tuple[float, float], width: float, label: int
) -> None:
    """A limb segment: a thick line with round ends."""
    thickness = max(1, round(width))
    cv2.line(img, _pt(*a), _pt(*b), label, thickness, cv2.LINE_8, _SHIFT)


def _draw_walker(camera: GroundCamera, walker: Walker, t: float) -> Sprite | None:
    """The person at time t as a label sprite, or None if it is not walking now."""
    state = walker.state(t)
    if state is None:
        return None
    X, Z, dX, dZ, walked = state
    s = camera.f * walker.height_m / Z  # body height in pixels
    foot_x = camera.image_x(X, Z)
    foot_y = camera.image_y(0.0, Z)
    # lateral share of the motion as seen by the camera (1 = walking across the image)
    across = abs(dX)
    direction = 1.0 if dX >= 0 else -1.0
    toward = dZ < -0.35  # facing the camera: face visible
    amp = 1.0 if walker.moving(t) else 0.0
    phase = 2 * math.pi * walked / walker.cycle_m

    pad = 3.0
    w_crop = math.ceil(0.75 * s * walker.build + 2 * pad)
    h_crop = math.ceil(1.06 * s + 2 * pad)
    ox = foot_x - w_crop / 2  # crop origin in frame pixels (fractional)
    oy = foot_y - h_crop + pad
    x0, y0 = math.floor(ox), math.floor(oy)
    fx, fy = foot_x - x0, foot_y - y0  # foot point in crop coordinates
    img = np.zeros((h_crop, w_crop), np.uint8)

    lateral = 0.3 + 0.7 * across  # how much of a swing shows sideways
    b = walker.build
    thigh, shin, foot_h = 0.245 * s, 0.245 * s, 0.035 * s
    hip_half = 0.07 * s * b * (1.0 - 0.6 * across)
    legs = []
    for k in (0, 1):
        leg_phase = phase + k * math.pi
        a = amp * 0.42 * math.sin(leg_phase)
        bend = amp * (0.1 + 0.55 * max(0.0, math.sin(leg_phase + 1.9)))
        legs.append((a, bend))
    drop = max(math.cos(a) * thigh + math.cos(a - bend) * shin for a, bend in legs)
    hip_y = fy - foot_h - drop
    hip_x = fx
    shoulder_y = hip_y - 0.30 * s
    shoulder_x = hip_x + direction * 0.02 * s * across * amp
    shoulder_half = 0.115 * s * b * (1.0 - 0.55 * across)
    waist_half = 0.085 * s * b * (1.0 - 0.45 * across)

    def leg(k: int, label: int, shoe: int) -> None:
        a, bend = legs[k]
        side = (-1 if k == 0 else 1) * hip_half
        hip = (hip_x + side, hip_y)
        knee = (hip[0] + direction * math.sin(a) * thigh * lateral, hip[1] + math.cos(a) * thigh)
        ankle = (
            knee[0] + direction * math.sin(a - bend) * shin * lateral,
            knee[1] + math.cos(a - bend) * shin,
        )
        _limb(img, hip, knee, 0.085 * s * b, label)
        _limb(img, knee, ankle, 0.065 * s * b, label)
        toe = (ankle[0] + direction * 0.07 * s * across, ankle[1] + foot_h * 0.6)
        _limb(img, (ankle[0], ankle[1] + foot_h * 0.3), toe, 0.045 * s + 1, shoe)

    def arm(k: int, label: int) -> None:
        a = -amp * 0.38 * math.sin(phase + k * math.pi)
        # arms hang beside the torso (seen from the front) or over it (from the side)
        side = (-1 if k == 0 else 1) * (shoulder_half * 0.92 + 0.035 * s * b * (1.0 - across))
        shoulder = (shoulder_x + side, shoulder_y + 0.03 * s)
        elbow = (
            shoulder[0] + direction * math.sin(a) * 0.17 * s * lateral,
            shoulder[1] + math.cos(a) * 0.17 * s,
        )
        fore = a + 0.25 + 0.35 * amp * max(0.0, math.sin(phase + k * math.pi + math.pi))
        hand = (
            elbow[0] + direction * math.sin(fore) * 0.16 * s * lateral,
            elbow[1] + math.cos(fore) * 0.16 * s,
        )
        _limb(img, shoulder, elbow, 0.06 * s * b, label)
        _limb(img, elbow, hand, 0.048 * s * b, label if walker.long_sleeves else _SKIN)
        cv2.circle(img, _pt(*hand), round(0.028 * s * _ONE), _SKIN, -1, cv2.LINE_8, _SHIFT)

    # far limbs first (darker), then torso, then near limbs and head
    leg(1, _TROUSERS_BACK, _SHOES)
    arm(1, _SHIRT_BACK)
    torso = np.array(
        [
            _pt(hip_x - waist_half, hip_y + 0.04 * s),
            _pt(hip_x + waist_half, hip_y + 0.04 * s),
            _pt(shoulder_x + shoulder_half, shoulder_y + 0.03 * s),
            _pt(shoulder_x + shoulder_half * 0.7, shoulder_y - 0.005 * s),
            _pt(shoulder_x - shoulder_half * 0.7, shoulder_y - 0.005 * s),
            _pt(shoulder_x - shoulder_half, shoulder_y + 0.03 * s),
        ],
        np.int32,
    )
    # hips and seat in trousers colour under the shirt's hem
    _limb(
        img,
        (hip_x - hip_half, hip_y + 0.02 * s),
        (hip_x + hip_half, hip_y + 0.02 * s),
        0.1 * s,
        _TROUSERS,
    )
    leg(0, _TROUSERS, _SHOES)
    cv2.fillConvexPoly(img, torso, _SHIRT, cv2.LINE_8, _SHIFT)
    arm(0, _SHIRT)
    head_r = 0.062 * s
    head = (shoulder_x + direction * 0.012 * s * across, shoulder_y - 0.035 * s - head_r)
    _limb(img, (shoulder_x, shoulder_y), head, 0.05 * s, _SKIN)  # neck
    cv2.circle(img, _pt(*head), round(head_r * _ONE), _HAIR, -1, cv2.LINE_8, _SHIFT)
    if across > 0.5 or toward:
        # the face: toward the camera it fills the head below the hairline; sideways it is
        # the front half of the head
        face_dx = direction * 0.35 * head_r * across if across > 0.5 else 0.0
        face = (head[0] + face_dx, head[1] + 0.22 * head_r)
        cv2.circle(img, _pt(*face), round(0.82 * head_r * _ONE), _SKIN, -1, cv2.LINE_8, _SHIFT)
    return Sprite(walker.id, Z, x0, y0, img)


# --- the scene's layout -----------------------------------------------------------------

_SKIN_TONES = [(185, 205, 235), (150, 180, 225), (110, 145, 195), (80, 110, 160), (55, 75, 110)]
_HAIR_TONES = [(20, 20, 25), (30, 45, 70), (40, 80, 130), (120, 170, 210), (150, 150, 155)]
_SHIRTS = [
    (40, 40, 200), (200, 80, 30), (40, 170, 40), (30, 200, 230), (230, 230, 230), (140, 40, 140),
    (20, 20, 20), (200, 160, 60), (60, 120, 240), (170, 170, 60), (90, 90, 90), (180, 110, 250),
]  # fmt: skip
_TROUSERS_COLOURS = [
    (90, 50, 30), (30, 30, 30), (120, 110, 100), (60, 70, 80), (160, 130, 90), (40, 40, 110),
    (200, 200, 200), (60, 90, 60),
]  # fmt: skip


def _palette(rng: np.random.Generator, *, thermal: bool) -> U8:
    palette = np.zeros((_LABELS, 3), np.uint8)
    if thermal:
        # apparent temperature as grey: bare skin hottest, clothing insulates, shoes coolest
        warm_skin = float(rng.uniform(215, 240))
        warm_hair = float(rng.uniform(150, 185))
        warm_shirt = float(rng.uniform(175, 210))
        warm_legs = float(rng.uniform(165, 200))
        values = [0, warm_skin, warm_hair, warm_shirt, warm_shirt - 8, warm_legs, warm_legs - 8]
        values.append(float(rng.uniform(110, 140)))
        palette[:] = np.array(values, np.float64).round().astype(np.uint8)[:, None]
        return palette
    pick = rng.integers
    skin = np.array(_SKIN_TONES[pick(len(_SKIN_TONES))], np.float64)
    hair = np.array(_HAIR_TONES[pick(len(_HAIR_TONES))], np.float64)
    shirt = np.array(_SHIRTS[pick(len(_SHIRTS))], np.float64) * rng.uniform(0.85, 1.1)
    trousers = np.array(_TROUSERS_COLOURS[pick(len(_TROUSERS_COLOURS))], np.float64)
    trousers *= rng.uniform(0.85, 1.1)
    shoes = np.array([30, 30, 35], np.float64) if rng.random() < 0.7 else np.array([220, 220, 220])
    rows = [np.zeros(3), skin, hair, shirt, shirt * 0.72, trousers, trousers * 0.72, shoes]
    palette[:] = np.clip(np.array(rows), 0, 255).round().astype(np.uint8)
    return palette


def _walker(
    rng: np.random.Generator,
    walker_id: int,
    path: list[tuple[float, float]],
    t_at_start: float,
    *,
    thermal: bool,
    speed: float | None = None,
    pause: bool = False,
) -> Walker:
    height = float(rng.normal(1.72, 0.08))
    height = min(max(height, 1.5), 1.95)
    jogger = speed is None and rng.random() < 0.12
    # both looks drawn always: the thermal scene is the same scene, seen differently
    palettes = _palette(rng, thermal=False), _palette(rng, thermal=True)
    if speed is None:
        speed = float(rng.uniform(2.4, 3.2) if jogger else rng.uniform(0.9, 1.7))
    cycle = 2 * (0.9 if jogger else 0.41) * height * math.sqrt(speed / 1.3)
    points = np.array(path, np.float64)
    length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    pause_at = float(rng.uniform(0.3, 0.7) * length) if pause else math.inf
    return Walker(
        id=walker_id,
        height_m=height,
        build=float(rng.uniform(0.9, 1.15)),
        palette=palettes[1] if thermal else palettes[0],
        long_sleeves=bool(rng.random() < 0.5),
        path=points,
        speed=speed,
        t0=t_at_start,
        cycle_m=cycle,
        pause_at=pause_at,
        pause_s=float(rng.uniform(2.0, 5.0)) if pause else 0.0,
    )


_PERIOD = 24.0  # seconds: the scripted encounters repeat with this period


def _plan_walkers(
    camera: GroundCamera, params: SceneParams, seed: int, occluders: list[Occluder]
) -> list[Walker]:
    """Per period of `_PERIOD` seconds: scripted encounters (someone behind a pillar, a
    near/far crossing, an approach, a recede with a pause) plus walkers with random entries,
    exits and waypoints. Each period has its own random stream, so the first N frames of a
    scene do not depend on its length; period 0 also fills the plaza before frame 0."""
    duration = params.frame_count / params.fps
    walkers: list[Walker] = []
    period = 0
    while period * _PERIOD < duration:
        rng = np.random.default_rng([seed, 3, period])
        _scripted(camera, params, rng, period, occluders, walkers)
        start, end = period * _PERIOD, (period + 1) * _PERIOD
        if period == 0:
            start -= 20.0  # people already on their way at frame 0
        count = round(params.people_per_minute * (end - start) / 60.0)
        for _ in range(count):
            _random_walker(camera, params, rng, float(rng.uniform(start, end)), walkers)
        period += 1
    return walkers


def _scripted(
    camera: GroundCamera,
    params: SceneParams,
    rng: np.random.Generator,
    period: int,
    occluders: list[Occluder],
    walkers: list[Walker],
) -> None:
    thermal = params.thermal
    near = camera.near_z
    start = period * _PERIOD + float(rng.uniform(1.0, 4.0))

    def across_at(z: float, x_cross: float, t_cross: float, speed: float, rightward: bool) -> None:
        edge = camera.half_width_m(z) + 1.0
        xs = (-edge, edge) if rightward else (edge, -edge)
        t_start = t_cross - abs(x_cross - xs[0]) / speed
        path = [(xs[0], z), (xs[1], z)]
        walkers.append(_walker(rng, len(walkers), path, t_start, thermal=thermal, speed=speed))

    # 1. someone passes behind a pillar (fully hidden for a moment)
    pillars = [o for o in occluders if o.kind == "pillar"]
    pillar = pillars[period % len(pillars)]
    pz = pillar.z
    px = (pillar.x0 + pillar.mask.shape[1] / 2 - camera.cx) * pz / camera.f
    z = pz + float(rng.uniform(3.0, 7.0))
    t_hidden = start + float(rng.uniform(0, 4))
    across_at(z, px * z / pz, t_hidden, float(rng.uniform(1.0, 1.5)), bool(rng.random() < 0.5))
    # 2. two people cross, one nearer than the other
    z_near = float(rng.uniform(near + 2.0, 18.0))
    z_far = z_near + float(rng.uniform(5.0, 12.0))
    t_cross = start + float(rng.uniform(6.0, 12.0))
    x_img = float(rng.uniform(-0.3, 0.3))  # where in the image they meet, of half-width
    rightward = bool(rng.random() < 0.5)
    speed_near, speed_far = float(rng.uniform(1.1, 1.5)), float(rng.uniform(1.0, 1.4))
    across_at(z_near, x_img * camera.half_width_m(z_near), t_cross, speed_near, rightward)
    across_at(z_far, x_img * camera.half_width_m(z_far), t_cross, speed_far, not rightward)
    # 3. someone approaches from far away and leaves at the bottom; someone recedes
    for toward in (True, False):
        x_far = float(rng.uniform(-0.5, 0.5)) * camera.half_width_m(_FAR_Z)
        x_near = float(rng.uniform(-0.4, 0.4)) * camera.half_width_m(near)
        path = [(x_far, _FAR_Z), (x_near, near * 0.62)]
        t = start + float(rng.uniform(0, 8) if toward else rng.uniform(8, 16))
        walkers.append(
            _walker(
                rng,
                len(walkers),
                path if toward else path[::-1],
                t,
                thermal=thermal,
                pause=not toward,
            )
        )


def _random_walker(
    camera: GroundCamera,
    params: SceneParams,
    rng: np.random.Generator,
    t_start: float,
    walkers: list[Walker],
) -> None:
    near = camera.near_z
    a, b = _edge_point(camera, rng), _edge_point(camera, rng)
    while abs(a[0] - b[0]) + abs(a[1] - b[1]) < 12.0:
        b = _edge_point(camera, rng)
    path = [a]
    if rng.random() < 0.5:
        z = float(rng.uniform(near + 1.0, _FAR_Z - 4))
        path.append((float(rng.uniform(-0.7, 0.7)) * camera.half_width_m(z), z))
    path.append(b)
    pause = bool(rng.random() < 0.2)
    walkers.append(_walker(rng, len(walkers), path, t_start, thermal=params.thermal, pause=pause))


def _edge_point(camera: GroundCamera, rng: np.random.Generator) -> tuple[float, float]:
    """A point just outside the walkable area seen by the camera: left, right, far or near."""
    side = rng.integers(4)
    near = camera.near_z
    if side < 2:
        z = float(rng.uniform(near + 1.0, _FAR_Z))
        x = camera.half_width_m(z) + 1.0
        return (-x if side == 0 else x, z)
    if side == 2:
        return (float(rng.uniform(-0.8, 0.8)) * camera.half_width_m(_FAR_Z), _FAR_Z)
    return (float(rng.uniform(-0.8, 0.8)) * camera.half_width_m(near), near * 0.62)


def _place_occluders(camera: GroundCamera, seed: int, *, thermal: bool) -> list[Occluder]:
    """Pillars, lamp poles, trees, a bench and a hedge on the plaza, far to near."""
    rng = np.random.default_rng([seed, 5])
    near = camera.near_z
    plan: list[tuple[str, float, float]] = []  # kind, X, Z

    def spot(z_lo: float, z_hi: float, spread: float) -> tuple[float, float]:
        for _ in range(100):
            z = float(rng.uniform(z_lo, z_hi))
            x = float(rng.uniform(-spread, spread)) * camera.half_width_m(z)
            # keep objects apart in the image so each stays recognisable
            if all(abs(camera.image_x(x, z) - camera.image_x(px, pz)) > 90 for _, px, pz in plan):
                return x, z
        return x, z

    for kind, count, z_lo, z_hi, spread in (
        ("pillar", 2, near + 4, 24.0, 0.6),
        ("pole", 3, near + 3, 34.0, 0.85),
        ("tree", 3, near + 8, 38.0, 0.9),
        ("bench", 1, near + 3, 22.0, 0.6),
        ("hedge", 1, 22.0, 34.0, 0.5),
    ):
        for _ in range(count):
            plan.append((kind, *spot(z_lo, z_hi, spread)))
    out = [_occluder(camera, kind, x, z, rng, thermal=thermal) for kind, x, z in plan]
    out.sort(key=lambda o: -o.z)
    return out


def _occluder(
    camera: GroundCamera, kind: str, X: float, Z: float, rng: np.random.Generator, *, thermal: bool
) -> Occluder:
    scale = camera.f / Z  # pixels per metre at this depth
    dims = {
        "pillar": (1.2, 3.2),
        "pole": (0.16, 5.5),
        "tree": (3.4, 6.0),
        "bench": (1.9, 0.9),
        "hedge": (4.5, 1.1),
    }
    width_m, height_m = dims[kind]
    w = max(3, math.ceil(width_m * scale) + 4)
    if kind == "pole":
        w = max(w, math.ceil(0.9 * scale) + 4)  # room for the lamp arm
    h = math.ceil(height_m * scale) + 4
    base_x = camera.image_x(X, Z)
    base_y = camera.image_y(0.0, Z)
    x0, y0 = math.floor(base_x - w / 2), math.floor(base_y - h + 2)
    channels = 1 if thermal else 3
    image = np.zeros((h, w, channels), np.uint8)
    mask = np.zeros((h, w), np.uint8)
    cx, by = base_x - x0, base_y - y0  # base point in crop coordinates

    def fill(
        points: list[tuple[float, float]], colour: tuple[float, float, float], grey: float
    ) -> None:
        poly = np.array([_pt(px, py) for px, py in points], np.int32)
        cv2.fillConvexPoly(image, poly, _colour(colour, grey, thermal), cv2.LINE_8, _SHIFT)
        cv2.fillConvexPoly(mask, poly, 1, cv2.LINE_8, _SHIFT)

    def rect(
        xa: float, ya: float, xb: float, yb: float, colour: tuple[float, float, float], grey: float
    ) -> None:
        fill([(xa, ya), (xb, ya), (xb, yb), (xa, yb)], colour, grey)

    def ellipse(
        c: tuple[float, float],
        axes: tuple[float, float],
        colour: tuple[float, float, float],
        grey: float,
    ) -> None:
        centre, ax = _pt(*c), (round(axes[0] * _ONE), round(axes[1] * _ONE))
        cv2.ellipse(
            image, centre, ax, 0, 0, 360, _colour(colour, grey, thermal), -1, cv2.LINE_8, _SHIFT
        )
        cv2.ellipse(mask, centre, ax, 0, 0, 360, 1, -1, cv2.LINE_8, _SHIFT)

    if kind == "pillar":
        r = 0.6 * scale
        top = by - 3.0 * scale
        poster = [_bgr(rng.uniform(40, 230, 3)) for _ in range(3)]
        rect(cx - r, top, cx + r, by, (150, 155, 160), 95)
        band = (by - top) / 3
        for i, colour in enumerate(poster):
            rect(
                cx - r * 0.97,
                top + band * i + 2,
                cx + r * 0.97,
                top + band * (i + 1) - 2,
                colour,
                90 + 6 * i,
            )
        ellipse((cx, top), (r * 1.1, max(2.0, 0.25 * scale)), (70, 90, 60), 85)
        _shade_cylinder(image, mask, cx, r)
    elif kind == "pole":
        r = max(1.0, 0.08 * scale)
        top = by - 5.3 * scale
        rect(cx - r, top, cx + r, by, (70, 70, 75), 80)
        rect(cx - r * 1.6, by - 0.5 * scale, cx + r * 1.6, by, (60, 60, 65), 78)
        rect(cx, top, cx + 0.6 * scale, top + max(1.5, 0.08 * scale), (70, 70, 75), 80)
        ellipse(
            (cx + 0.6 * scale, top + 0.1 * scale), (0.2 * scale, 0.09 * scale), (200, 240, 250), 250
        )
    elif kind == "tree":
        r = max(1.5, 0.16 * scale)
        rect(cx - r, by - 3.2 * scale, cx + r, by, (40, 60, 85), 70)
        for _ in range(9):
            dx = float(rng.normal(0, 0.55)) * scale
            dy = float(rng.normal(0, 0.45)) * scale
            rx = float(rng.uniform(0.7, 1.1)) * scale
            green = (
                float(rng.uniform(30, 60)),
                float(rng.uniform(90, 140)),
                float(rng.uniform(30, 70)),
            )
            ellipse(
                (cx + dx, by - 4.3 * scale + dy),
                (rx, rx * 0.85),
                green,
                55 + float(rng.uniform(0, 10)),
            )
        _mottle(image, mask, rng, 18 if not thermal else 6)
    elif kind == "bench":
        half = 0.95 * scale
        rect(cx - half, by - 0.5 * scale, cx + half, by - 0.42 * scale, (40, 90, 140), 90)  # seat
        rect(cx - half, by - 0.88 * scale, cx + half, by - 0.62 * scale, (40, 90, 140), 90)  # back
        for leg in (-0.85, 0.85):
            rect(
                cx + leg * half - 0.04 * scale,
                by - 0.88 * scale,
                cx + leg * half + 0.04 * scale,
                by,
                (50, 50, 50),
                85,
            )
    else:  # hedge
        half = 2.25 * scale
        rect(cx - half, by - 1.05 * scale, cx + half, by, (40, 110, 50), 60)
        _mottle(image, mask, rng, 25 if not thermal else 6)
    bool_mask = mask.astype(bool)
    pixels: U8 = image if not thermal else image[:, :, 0]
    return Occluder(kind, Z, x0, y0, pixels, bool_mask)


def _bgr(values: NDArray[np.float64]) -> tuple[float, float, float]:
    return float(values[0]), float(values[1]), float(values[2])


def _colour(colour: tuple[float, float, float], grey: float, thermal: bool) -> tuple[float, ...]:
    return (grey,) if thermal else colour


def _shade_cylinder(image: U8, mask: U8, cx: float, r: float) -> None:
    """Darken a cylinder towards its edges (light from the front)."""
    cols = np.arange(image.shape[1], dtype=np.float32)
    u = np.clip(np.abs(cols - cx) / max(r, 1.0), 0, 1)
    shade = 1.0 - 0.45 * u**2
    image[:] = np.clip(image * shade[None, :, None], 0, 255).astype(np.uint8)


def _mottle(image: U8, mask: U8, rng: np.random.Generator, amount: float) -> None:
    """Leafy texture: blotchy brightness noise inside the mask."""
    h, w = mask.shape
    small = rng.normal(0, amount, (max(2, h // 4), max(2, w // 4))).astype(np.float32)
    blotch = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    fine = rng.normal(0, amount * 0.4, (h, w)).astype(np.float32)
    out = image.astype(np.float32) + (blotch + fine)[:, :, None]
    image[:] = np.clip(out, 0, 255).astype(np.uint8)


def _value_noise(rng: np.random.Generator, shape: tuple[int, int], cells: int) -> F32:
    """Smooth noise in [-1, 1]: random values on a coarse grid, upsampled bicubically."""
    h, w = shape
    coarse = rng.uniform(-1, 1, (max(2, h // cells + 2), max(2, w // cells + 2))).astype(np.float32)
    return np.asarray(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC), np.float32)


def _background(camera: GroundCamera, seed: int, *, thermal: bool) -> U8:
    """Sky, buildings and textured ground with perspective (BGR, or grey when thermal)."""
    rng = np.random.default_rng([seed, 1])
    W, H = camera.width, camera.height
    rows = np.arange(H, dtype=np.float32)[:, None]
    cols = np.arange(W, dtype=np.float32)[None, :]
    hy = camera.horizon_y

    # sky: a vertical gradient
    sky_t = np.clip(rows / max(hy, 1.0), 0, 1)
    sky = np.concatenate(
        [(235 - 45 * (1 - sky_t)), (215 - 60 * (1 - sky_t)), (200 - 90 * (1 - sky_t))], axis=1
    )[:, None, :] * np.ones((1, W, 1), np.float32)

    # ground: every pixel below the horizon is a point (X, Z) on the plane
    dy = np.maximum(rows - hy, 0.5)
    Z = camera.f * camera.height_m / dy  # (H, 1)
    X = (cols - camera.cx) * Z / camera.f  # (H, W)
    footprint = Z / camera.f  # metres per pixel at that row
    # paving: 0.8 m slabs, joints fade out where they get thinner than a pixel
    joint_w = 0.03
    fx = np.abs(((X / 0.8) % 1.0) - 0.5) * 0.8
    fz = np.abs(((Z / 0.8) % 1.0) - 0.5) * 0.8
    edge = 0.4 - np.maximum(fx, fz)  # distance to the nearest joint, metres
    joint = np.clip((joint_w + footprint - edge) / np.maximum(footprint, 1e-3), 0, 1)
    joint *= np.clip(joint_w / np.maximum(footprint, joint_w), 0, 1)
    stain = _value_noise(rng, (H, W), 40) * 0.5 + _value_noise(rng, (H, W), 9) * 0.3
    grass = np.abs(X) > (9.0 + 2.0 * _value_noise(rng, (H, W), 120))
    grain = rng.normal(0, 1, (H, W)).astype(np.float32)
    base = np.where(grass, 0.0, 1.0)
    paving = np.stack([150 + 0 * X, 148 + 0 * X, 142 + 0 * X], axis=2)
    lawn = np.stack([45 + 0 * X, 120 + 0 * X, 70 + 0 * X], axis=2)
    ground = paving * base[:, :, None] + lawn * (1 - base[:, :, None])
    ground *= (1.0 + 0.12 * stain - 0.35 * joint * base)[:, :, None]
    ground += (grain * (6 + 10 * (1 - base)))[:, :, None]
    # haze towards the horizon
    haze = np.clip((Z - 25.0) / 120.0, 0, 0.6)[:, :, None]
    ground = ground * (1 - haze) + np.array([200, 195, 190], np.float32) * haze
    image = np.where(rows[:, :, None] >= hy, ground, sky)
    is_sky = np.broadcast_to(rows < hy, (H, W)).copy()

    # buildings: facades standing at _BUILDING_Z, windows in rows
    scale = camera.f / _BUILDING_Z
    base_y = camera.image_y(0.0, _BUILDING_Z)
    x = -float(rng.uniform(0, 60))
    while x < W:
        width = float(rng.uniform(9, 24)) * scale
        gap = float(rng.uniform(0, 6)) * scale if rng.random() < 0.4 else 0.0
        height = float(rng.uniform(8, 30)) * scale
        colour = np.array(rng.uniform(70, 200, 3), np.float32)
        xa, xb = round(x), round(x + width)
        ya = max(0, round(base_y - height))
        yb = round(base_y)
        image[ya:yb, max(xa, 0) : max(xb, 0)] = colour
        is_sky[ya:yb, max(xa, 0) : max(xb, 0)] = False
        floor = 3.2 * scale
        win_w, win_h = 1.2 * scale, 1.5 * scale
        lit = np.array([150, 200, 230], np.float32)
        dark = colour * 0.45
        yy = yb - floor
        while yy - win_h > ya:
            xx = xa + 1.0 * scale
            while xx + win_w < xb:
                c = lit if rng.random() < 0.15 else dark
                r0, r1, c0, c1 = round(yy - win_h), round(yy), round(xx), round(xx + win_w)
                image[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)] = c
                xx += 2.2 * scale
            yy -= floor
        x += width + gap
    image = np.clip(image, 0, 255).astype(np.uint8)
    if not thermal:
        return image
    return _thermal_background(image, camera, rng, is_sky, grass)


def _thermal_background(
    visible: U8,
    camera: GroundCamera,
    rng: np.random.Generator,
    is_sky: NDArray[np.bool_],
    grass: NDArray[np.bool_],
) -> U8:
    """Cool, cluttered ground and walls; some hot windows, vents and a warm car."""
    H, W = visible.shape[:2]
    grey = cv2.cvtColor(visible, cv2.COLOR_BGR2GRAY).astype(np.float32)
    # thermal contrast of the scene is low: compress the visible structure around ~80
    image = 70 + 0.25 * (grey - 128) + 10 * _value_noise(rng, (H, W), 30)
    image[grass] -= 12
    image[is_sky] = 35.0  # a clear sky is cold
    # hot clutter on the ground: a parked car's bonnet and a few manhole vents
    z = float(rng.uniform(25, 35))
    scale = camera.f / z
    cx = camera.image_x(float(rng.choice([-1, 1])) * camera.half_width_m(z) * 0.75, z)
    cy = camera.image_y(0.0, z)
    cv2.rectangle(
        image,
        (round(cx - 2.2 * scale), round(cy - 1.4 * scale)),
        (round(cx + 2.2 * scale), round(cy)),
        110.0,
        -1,
    )
    cv2.rectangle(
        image,
        (round(cx - 2.2 * scale), round(cy - 1.0 * scale)),
        (round(cx - 0.6 * scale), round(cy - 0.4 * scale)),
        215.0,
        -1,
    )
    for _ in range(3):
        z = float(rng.uniform(12, 40))
        s = camera.f / z
        vx, vy = (
            camera.image_x(float(rng.uniform(-0.8, 0.8)) * camera.half_width_m(z), z),
            camera.image_y(0, z),
        )
        cv2.ellipse(
            image,
            (round(vx), round(vy)),
            (max(2, round(0.5 * s)), max(1, round(0.15 * s))),
            0,
            0,
            360,
            190.0,
            -1,
        )
    return np.asarray(np.clip(image, 0, 255), np.float32).astype(np.uint8)


# --- writing a scene to disk ------------------------------------------------------------


def write_scene(
    out_dir: str | Path, seed: int, frames: int, *, thermal: bool = False
) -> tuple[Path, Path]:
    """Write `scene.avi` (MJPG) and `gt.json` of `synthetic:SEED` into `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    source = SceneSource(
        seed, thermal=thermal, params=SceneParams(frame_count=frames, thermal=thermal)
    )
    video = out / "scene.avi"
    # MJPG: every frame a keyframe, so any reader seeks exactly and cheaply
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), source.fps, source.size)
    if not writer.isOpened():
        raise UsageError(f"cannot write {video}: no MJPG encoder or unwritable directory")
    try:
        for index in range(frames):
            writer.write(source.read(index))
    finally:
        writer.release()
    gt_path = out / "gt.json"
    save_ground_truth(source.ground_truth, gt_path)
    return video, gt_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m ptzd.sim.scene", description="write a synthetic scene and its ground truth"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=300, help="number of frames (25 fps)")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--thermal", action="store_true", help="the thermal variant")
    parser.add_argument("--png", type=int, metavar="FRAME", help="also save this frame as PNG")
    args = parser.parse_args(argv)
    if not 1 <= args.frames <= 1_000_000:
        print(f"error: --frames must be 1..1000000, got {args.frames}", file=sys.stderr)
        return 2
    try:
        video, gt = write_scene(args.out, args.seed, args.frames, thermal=args.thermal)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.png is not None:
        source = SceneSource(
            args.seed, thermal=args.thermal, params=SceneParams(frame_count=args.frames)
        )
        cv2.imwrite(str(Path(args.out) / f"frame{args.png:05d}.png"), source.read(args.png))
    print(f"{video}\n{gt}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
