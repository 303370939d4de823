"""Transforms along a chain of tf frames: the path between two frames, the composition of its links, and moving
links brought to one set of stamps (SLERP for rotation, linear for translation).

A link (parent, child) is the pose of the child frame in the parent frame, as tf2 records it: a point p_child maps
to p_parent = R p_child + t. Rotations are scipy Rotations (quaternions x, y, z, w, the project's order inside).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

MAX_GAP_FACTOR = 3.0  # a moving link is not bridged across a gap longer than this x its median period (as sequence.py)


@dataclass(frozen=True)
class Step:
    """One link of a path: the recorded pair (parent, child), traversed child -> parent when `inverted`."""

    parent: str
    child: str
    inverted: bool = False

    @property
    def pair(self) -> tuple[str, str]:
        return self.parent, self.child

    def __str__(self) -> str:
        return f"{self.parent} -> {self.child}"


def find_path(pairs: Iterable[tuple[str, str]], start: str, goal: str) -> list[Step] | None:
    """The shortest path of links from `start` to `goal`, a link usable in either direction; None: none joins them.
    Ties go to the link first in `pairs`, so the path does not depend on set order."""
    neighbours: dict[str, list[tuple[str, Step]]] = {}
    for parent, child in pairs:
        neighbours.setdefault(parent, []).append((child, Step(parent, child)))
        neighbours.setdefault(child, []).append((parent, Step(parent, child, inverted=True)))
    came: dict[str, tuple[str, Step] | None] = {start: None}
    todo = deque([start])
    while todo:
        frame = todo.popleft()
        if frame == goal:
            break
        for nxt, step in neighbours.get(frame, []):
            if nxt not in came:
                came[nxt] = (frame, step)
                todo.append(nxt)
    if goal not in came:
        return None
    path: list[Step] = []
    frame = goal
    while (prev := came[frame]) is not None:
        frame, step = prev
        path.append(step)
    return path[::-1]


def path_frames(path: Sequence[Step], start: str) -> list[str]:
    """The frames a path visits, `start` first."""
    frames = [start]
    for s in path:
        frames.append(s.parent if s.inverted else s.child)
    return frames


def invert(rot: Rotation, trans: np.ndarray) -> tuple[Rotation, np.ndarray]:
    """(R, t)^-1 = (R^T, -R^T t)."""
    inv = rot.inv()
    return inv, -inv.apply(trans)


def compose(links: Sequence[tuple[Rotation, np.ndarray]], inverted: Sequence[bool]) -> tuple[Rotation, np.ndarray]:
    """T_1 T_2 ... T_k (each inverted first where `inverted` says) as (R, t). A link is N samples (Rotation of N,
    t of shape (N, 3)) or one constant (a single Rotation, t of shape (3,)), broadcast against the others."""
    if len(links) != len(inverted):
        raise ValueError(f"{len(links)} links but {len(inverted)} inverted flags")
    rot, trans = Rotation.identity(), np.zeros(3)
    for (r, t), inv in zip(links, inverted, strict=True):
        if inv:
            r, t = invert(r, np.asarray(t, dtype=np.float64))
        trans = trans + rot.apply(t)
        rot = rot * r
    return rot, trans


def coverage(
    t_ns: np.ndarray, at_ns: np.ndarray, max_gap_factor: float = MAX_GAP_FACTOR
) -> tuple[np.ndarray, np.ndarray]:
    """Where a link sampled at `t_ns` (sorted, unique) can be interpolated at `at_ns`: (outside, in_gap) boolean
    masks of `at_ns`: outside its first-to-last span, or between two samples more than `max_gap_factor` x its median
    period apart (a stamp on a sample is never in a gap)."""
    outside = (at_ns < t_ns[0]) | (at_ns > t_ns[-1])
    if len(t_ns) < 2:
        return outside, np.zeros(len(at_ns), dtype=bool)
    period = float(np.median(np.diff(t_ns)))
    j = np.clip(np.searchsorted(t_ns, at_ns, side="right") - 1, 0, len(t_ns) - 2)
    span = t_ns[j + 1] - t_ns[j]
    exact = (at_ns == t_ns[j]) | (at_ns == t_ns[j + 1])
    in_gap = ~outside & ~exact & (span > max_gap_factor * period)
    return outside, in_gap


def resample(t_ns: np.ndarray, rot: Rotation, trans: np.ndarray, at_ns: np.ndarray) -> tuple[Rotation, np.ndarray]:
    """A link sampled at `t_ns` (sorted, unique int ns) at the stamps `at_ns` (within t_ns[0]..t_ns[-1]): SLERP for
    the rotation, linear for the translation. Times are taken relative to t_ns[0] in int ns before float64."""
    if len(t_ns) == 1:
        if (at_ns != t_ns[0]).any():
            raise ValueError("a link of one sample is known only at its stamp")
        return Rotation.from_quat(np.repeat(rot.as_quat().reshape(1, 4), len(at_ns), 0)), np.repeat(
            trans.reshape(1, 3), len(at_ns), 0
        )
    x = (t_ns - t_ns[0]).astype(np.float64)
    xi = (at_ns - t_ns[0]).astype(np.float64)
    if xi.size and (xi.min() < 0 or xi.max() > x[-1]):
        raise ValueError("stamps outside the link's samples: drop them first (see coverage)")
    r = Slerp(x, rot)(xi)
    t = np.column_stack([np.interp(xi, x, trans[:, k]) for k in range(3)])
    return r, t
