"""Procedural figures for tests and codebook bootstrapping: walkers and non-human blobs.

A walker is drawn from proportions of an adult (head ~1/7.5 of height, shoulders ~1/4) with
legs and arms swinging by a gait phase, so a sequence of phases gives the silhouettes a
background subtractor sees of a person walking across a still view.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

U8 = NDArray[np.uint8]


def draw_walker(
    image: U8,
    x: float,
    y: float,
    height: float,
    phase: float,
    colour: tuple[int, int, int] | int,
    *,
    facing: int = 1,
) -> tuple[int, int, int, int]:
    """Draw a walking person whose box top-left is about (x, y); return its tight box.

    `phase` is the gait angle in radians (legs swing with sin(phase)); `facing` +1/-1 only
    leans the torso slightly. The returned box is measured on the drawn pixels.
    """
    mask = np.zeros(image.shape[:2], dtype=np.uint8)
    H = float(height)
    cx = x + 0.17 * H
    swing = 0.38 * math.sin(phase)
    lean = 0.02 * H * facing
    head_r = max(1, round(0.065 * H))
    cv2.circle(mask, (round(cx + lean), round(y + head_r)), head_r, 255, -1, cv2.LINE_AA)
    shoulder_y = y + 0.16 * H
    hip_y = y + 0.52 * H
    torso = np.array(
        [
            [cx + lean - 0.115 * H, shoulder_y],
            [cx + lean + 0.115 * H, shoulder_y],
            [cx + 0.09 * H, hip_y],
            [cx - 0.09 * H, hip_y],
        ],
        dtype=np.float64,
    )
    cv2.fillConvexPoly(mask, np.round(torso).astype(np.int32), 255, cv2.LINE_AA)
    cv2.line(
        mask,
        (round(cx + lean), round(y + head_r)),
        (round(cx + lean), round(shoulder_y)),
        255,
        max(1, round(0.06 * H)),
    )
    leg_len = 0.48 * H
    leg_w = max(1, round(0.075 * H))
    for side, sign in ((-1, 1.0), (1, -1.0)):
        hip = (cx + side * 0.05 * H, hip_y)
        angle = sign * swing
        foot = (hip[0] + leg_len * math.sin(angle), hip_y + leg_len * math.cos(angle))
        cv2.line(mask, (round(hip[0]), round(hip[1])), (round(foot[0]), round(foot[1])), 255, leg_w)
    arm_len = 0.33 * H
    arm_w = max(1, round(0.045 * H))
    for side, sign in ((-1, -1.0), (1, 1.0)):
        sh = (cx + lean + side * 0.11 * H, shoulder_y + 0.02 * H)
        angle = sign * swing * 0.8
        hand = (sh[0] + arm_len * math.sin(angle), sh[1] + arm_len * math.cos(angle))
        cv2.line(mask, (round(sh[0]), round(sh[1])), (round(hand[0]), round(hand[1])), 255, arm_w)
    image[mask > 127] = colour
    bx, by, bw, bh = cv2.boundingRect((mask > 127).astype(np.uint8))
    return int(bx), int(by), int(bw), int(bh)


def walker_silhouette(height: int, phase: float, *, facing: int = 1) -> NDArray[np.bool_]:
    """A single walker's mask cropped to its box."""
    canvas = np.zeros((height + 8, height), dtype=np.uint8)
    bx, by, bw, bh = draw_walker(canvas, height * 0.3, 2, height, phase, 255, facing=facing)
    out: NDArray[np.bool_] = canvas[by : by + bh, bx : bx + bw] > 0
    return out


def noisy_background(
    width: int, height: int, rng: np.random.Generator, *, noise: float = 4.0
) -> U8:
    """A textured grey-ish BGR scene (smooth gradients and blobs) plus per-pixel noise."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    base = 90 + 40 * np.sin(xx / 57.0) * np.cos(yy / 41.0) + 30 * (yy / height)
    scene = np.stack([base, base * 0.9 + 10, base * 1.1 - 5], axis=2)
    for _ in range(12):
        cx, cy = rng.uniform(0, width), rng.uniform(0, height)
        r = rng.uniform(10, 60)
        cv2.circle(
            scene, (int(cx), int(cy)), int(r), tuple(float(v) for v in rng.uniform(40, 200, 3)), -1
        )
    scene += rng.normal(0.0, noise, scene.shape).astype(np.float32)
    out: U8 = np.clip(scene, 0, 255).astype(np.uint8)
    return out


def add_noise(image: U8, rng: np.random.Generator, sigma: float = 3.0) -> U8:
    noisy = image.astype(np.float32) + rng.normal(0.0, sigma, image.shape).astype(np.float32)
    out: U8 = np.clip(noisy, 0, 255).astype(np.uint8)
    return out


class FigureScene:
    """A still view with procedural walkers crossing it, with exact ground-truth boxes.

    Deterministic in `seed`; frame `i` is computed directly, so frames can be read in any
    order. Walkers move horizontally at 0.8-3 px/frame, 60-170 px tall, possibly crossing.
    `distractors` adds a swaying tree and a car driving by (non-human motion).
    """

    def __init__(
        self,
        seed: int,
        *,
        width: int = 640,
        height: int = 480,
        frame_count: int = 300,
        walkers: int = 3,
        distractors: bool = False,
        fps: float = 10.0,
    ) -> None:
        self.size = (width, height)
        self.fps = fps
        self.frame_count = frame_count
        self.seed = seed
        self.distractors = distractors
        rng = np.random.default_rng(seed)
        self._background = noisy_background(width, height, rng, noise=0.0)
        self._walkers: list[tuple[float, float, float, float, int, tuple[int, int, int]]] = []
        for _ in range(walkers):
            h = float(rng.uniform(60, 170))
            speed = float(rng.uniform(0.8, 3.0)) * (1 if rng.random() < 0.5 else -1)
            y = float(rng.uniform(0, height - h - 1))
            start = float(rng.uniform(-0.3, 0.6)) * frame_count
            colour = tuple(int(v) for v in rng.integers(0, 256, 3))
            if abs(int(np.mean(colour)) - 120) < 40:
                colour = (int(colour[0]) // 4, int(colour[1]) // 4, int(colour[2]) // 4)
            self._walkers.append((h, speed, y, start, len(self._walkers), colour))  # type: ignore[arg-type]
        self._rng_seed = int(rng.integers(0, 2**31))
        self._cache: tuple[int, U8, list[tuple[int, int, int, int]]] | None = None

    def _walker_x(
        self, walker: tuple[float, float, float, float, int, tuple[int, int, int]], i: int
    ) -> float:
        h, speed, _, start, _, _ = walker
        t = i - start
        width = 0.4 * h
        x = t * abs(speed)
        return x - width if speed > 0 else self.size[0] - x

    def read(self, i: int) -> U8:
        frame, _ = self._render(i)
        return frame

    def boxes(self, i: int) -> list[tuple[int, int, int, int]]:
        _, boxes = self._render(i)
        return boxes

    def float_boxes(self, i: int) -> list[tuple[float, float, float, float]]:
        return [(float(x), float(y), float(w), float(h)) for x, y, w, h in self.boxes(i)]

    def _render(self, i: int) -> tuple[U8, list[tuple[int, int, int, int]]]:
        if self._cache is not None and self._cache[0] == i:
            return self._cache[1], self._cache[2]
        frame, boxes = self._draw(i)
        self._cache = (i, frame, boxes)
        return frame, boxes

    def _draw(self, i: int) -> tuple[U8, list[tuple[int, int, int, int]]]:
        frame = self._background.copy()
        W, Hh = self.size
        if self.distractors:
            sway = 6.0 * math.sin(i * 0.7)
            cv2.ellipse(frame, (int(560 + sway), 120), (45, 60), 0, 0, 360, (40, 110, 40), -1)
            cv2.rectangle(frame, (552, 170), (568, 260), (30, 60, 90), -1)
            car_x = int((i * 6) % (W + 200)) - 200
            cv2.rectangle(frame, (car_x, 380), (car_x + 160, 440), (150, 40, 40), -1)
            cv2.rectangle(frame, (car_x + 30, 350), (car_x + 120, 382), (120, 30, 30), -1)
        boxes: list[tuple[int, int, int, int]] = []
        for walker in self._walkers:
            h, speed, y, _, _, colour = walker
            x = self._walker_x(walker, i)
            if x < -0.5 * h or x > W + 0.1 * h:
                continue
            phase = (x / (0.25 * h)) % (2 * math.pi)
            box = draw_walker(frame, x, y, h, phase, colour, facing=1 if speed > 0 else -1)
            bx, by, bw, bh = box
            cx0, cy0 = max(0, bx), max(0, by)
            cx1, cy1 = min(W, bx + bw), min(Hh, by + bh)
            if cx1 - cx0 >= 4 and cy1 - cy0 >= 4:
                boxes.append((cx0, cy0, cx1 - cx0, cy1 - cy0))
        noise_rng = np.random.default_rng((self._rng_seed, i))
        return add_noise(frame, noise_rng), boxes
