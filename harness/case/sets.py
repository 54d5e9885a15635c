"""The standard load sets by name: the one registry a case's ``[loads] set`` reads.
A new load set is one function added here.

- ``basic2d`` / ``basic3d``: Deussen 1995 Fig. 4 / Fig. 7 on a box (harness/case/loadsets.py);
- ``homogeneous2d`` / ``homogeneous3d``: the constant stress states on any body;
- ``linear2d`` / ``linear3d``: those and the equilibrated linear stress states
  (harness/case/linear_states.py).
"""

from __future__ import annotations

from typing import Callable

from harness.case.linear_states import linear_states
from harness.case.loadsets import Frame, LoadCase, basic2d, basic3d, homogeneous2d, homogeneous3d


def linear2d(s: float, anchors, frame: Frame) -> tuple[LoadCase, ...]:
    return linear_states(2, s, anchors, frame)


def linear3d(s: float, anchors, frame: Frame) -> tuple[LoadCase, ...]:
    return linear_states(3, s, anchors, frame)


# name -> (dim, make(s, anchors, frame)): anchors are the body's anchor points (None for a
# box under the homogeneous sets), frame its centroid and size (harness/case/loads.py)
LOAD_SETS: dict[str, tuple[int, Callable[..., tuple[LoadCase, ...]]]] = {
    "basic2d": (2, basic2d),
    "basic3d": (3, basic3d),
    "homogeneous2d": (2, homogeneous2d),
    "homogeneous3d": (3, homogeneous3d),
    "linear2d": (2, linear2d),
    "linear3d": (3, linear3d),
}
ANCHORED = ("homogeneous", "linear")   # sets whose loads are held at anchor points (boxes: only linear)
