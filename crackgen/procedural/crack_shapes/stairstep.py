"""``stairstep`` family: the stepped crack of a masonry wall, running along its mortar joints.

Why along the joints: a running-bond wall that settles or shrinks cracks through its weakest
part, the mortar, so the crack climbs one course up a head joint, runs half a brick along
the bed joint to the next course's head joint, and climbs again. The joints themselves are
texture, never cracks (``crackgen.procedural.materials``): a model must tell the cracked
joint from the sound ones next to it, which is the hard negative of every masonry photo.

The joint layout is the wall's own (``JointGrid``, from ``materials.brick_joints``), so the
crack follows the very joints the material paints. Widths stay inside the joint (at most
0.6 of the mortar width either side of its centre), taper to both tips, and each segment
wanders a little inside the joint (jaggedness capped at 0.05).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crackgen.config.spec import CrackSpec
from crackgen.procedural.crack_shapes.fracture import main_profile
from crackgen.procedural.crack_shapes.paths import Path, arc_fraction, jagged_line

__all__ = ["JointGrid", "stairstep_paths"]

_MAX_JAGGED = 0.05  # inside a 10 mm joint the crack can only wander so far


@dataclass(frozen=True)
class JointGrid:
    """Mortar joint centre lines of a running-bond wall, in metres of the surface patch (x along u, y along v).

    Course r spans y + oy in [r pitch_y, (r + 1) pitch_y); mortar fills the first ``mortar_m`` of each pitch,
    and course r is shifted by ``bond`` x r pitches (mod 1), as ``materials._paint_bricks`` paints it."""

    pitch_x: float
    pitch_y: float
    mortar_m: float
    bond: float
    ox: float
    oy: float

    def bed_y(self, r: int) -> float:
        """Centre of the bed joint below course r."""
        return r * self.pitch_y + 0.5 * self.mortar_m - self.oy

    def head_x(self, r: int, c: int) -> float:
        """Centre of head joint c of course r."""
        sh = r * self.bond
        return c * self.pitch_x + 0.5 * self.mortar_m - self.ox - self.pitch_x * (sh - math.floor(sh))

    def course(self, y: float) -> int:
        return math.floor((y + self.oy) / self.pitch_y)

    def next_head(self, r: int, x: float, direction: int) -> float:
        """The first head joint of course r beyond ``x`` in ``direction`` (+1 right, -1 left)."""
        sh = r * self.bond
        base = 0.5 * self.mortar_m - self.ox - self.pitch_x * (sh - math.floor(sh))
        k = (x - base) / self.pitch_x
        c = math.floor(k + 1e-9) + 1 if direction > 0 else math.ceil(k - 1e-9) - 1
        return c * self.pitch_x + base


def stairstep_paths(spec: CrackSpec, half_width: float, joints: JointGrid, size_m: float,
                    rng: np.random.Generator) -> list[Path]:
    """``spec.count`` stepped cracks climbing 40-120 % of the patch height through the joints, in patch units;
    ``half_width`` (patch units) is the widest point, capped to stay inside the joint."""
    hw = min(half_width, 0.6 * joints.mortar_m / size_m)
    jag = min(spec.jaggedness, _MAX_JAGGED)
    paths = []
    for _ in range(max(1, spec.count)):
        direction = 1 if rng.random() < 0.5 else -1
        courses = max(2, int(math.ceil(rng.uniform(0.4, 1.2) * size_m / joints.pitch_y)))
        # start so that the staircase passes near a random point of the middle of the patch
        cy, cx = rng.uniform(0.3, 0.7, 2) * size_m
        r = joints.course(cy) - courses // 2
        run = courses // 2 * 0.5 * joints.pitch_x  # half a brick per course in running bond
        x = joints.next_head(r, cx - direction * run, direction)
        corners = [(x, joints.bed_y(r))]
        for _ in range(courses):
            corners.append((x, joints.bed_y(r + 1)))  # up the head joint of course r
            r += 1
            x = joints.next_head(r, x, direction)  # along the bed joint to the next course's head joint
            corners.append((x, joints.bed_y(r)))
        pts = np.asarray(corners[:-1], np.float64) / size_m  # ends on a head joint, not a bed-joint run
        xy = np.concatenate([jagged_line(a, b, jag, rng)[:-1] for a, b in zip(pts[:-1], pts[1:])] + [pts[-1:]])
        paths.append(Path(xy=xy, half_width=hw * main_profile(arc_fraction(xy), rng)))
    return paths
