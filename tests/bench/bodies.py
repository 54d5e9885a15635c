"""The test bar the bench tests mesh: [0, L] x [0, A] x [0, A], clamped on its x = 0 face
and loaded on its x = L face (harness/bench/heldout_bodies.py ``Body``)."""

from harness.bench import heldout_bodies as B

L, A = 0.5, 0.1
BAR = B.Body(
    "bar",
    lambda occ: occ.addBox(0, 0, 0, L, A, A),
    B._near(0, A / 2, A / 2),
    B._near(L, A / 2, A / 2),
    ((0, -1, 0), (0, 0, 1)),
    (0, 0, -1),
)
