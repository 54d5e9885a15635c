"""Same input, same bits: the sparse eigensolvers start from a seeded vector (ARPACK's own
random start changes from call to call within a process, which made two runs of a suite
differ in frequency columns at 1e-15 and in one L-BFGS-B trace)."""

import numpy as np

from harness.mechanics.modal import frequencies_arrays


def _lattice(n=24):
    """A triangulated n x n grid of springs with random constants (> 400 free dofs:
    the sparse path)."""
    rng = np.random.default_rng(11)
    xy = (
        np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1)
        .reshape(-1, 2)
        .astype(float)
    )
    idx = np.arange(n * n).reshape(n, n)
    springs = np.concatenate(
        [
            np.stack([idx[:-1, :].ravel(), idx[1:, :].ravel()], 1),
            np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
            np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()], 1),
        ]
    )
    k = rng.uniform(0.5, 2.0, len(springs))
    m = rng.uniform(0.5, 1.5, n * n)
    free = np.ones((n * n, 2), bool)
    free[idx[0, :]] = False  # clamp one edge
    return xy, springs, k, m, free.ravel()


def test_spring_network_frequencies_repeat_bit_for_bit():
    xy, springs, k, m, free = _lattice()
    assert free.sum() > 400
    a = frequencies_arrays(xy, springs, k, m, free, 6)
    b = frequencies_arrays(xy, springs, k, m, free, 6)
    assert np.array_equal(a, b)
    # and they are the right frequencies: dense generalised eigenproblem
    from harness.models.springs import incidence, stiffness_matrix

    K = stiffness_matrix(incidence(xy, springs), k).toarray()[free][:, free]
    M = np.repeat(m, 2)[free]
    lam = np.linalg.eigvalsh(K / np.sqrt(M)[:, None] / np.sqrt(M)[None, :])[:6]
    np.testing.assert_allclose(a, np.sqrt(lam) / (2 * np.pi), rtol=1e-8)


def test_reference_frequencies_repeat_bit_for_bit(tmp_path):
    import textwrap

    import reference
    from harness.case.reader import load_case

    p = tmp_path / "c.toml"
    p.write_text(
        textwrap.dedent("""
        name = "t"
        dim = 2
        [body]
        shape = "rectangle"
        size = [3.0, 1.0]
        [material]
        E = 100.0
        nu = 0.3
        density = 1.0
        [[loads.case]]
        name = "clamp"
        constraint = [{ part = "x0", components = ["all"] }]
        [reference]
        divisions = 6
        max_refine = 0
        """)
    )
    case = load_case(p)
    f = [reference.solve(case, cache=False).frequencies(6) for _ in range(2)]
    assert reference.solve(case, cache=False).disc.ndof > 400
    assert np.array_equal(f[0], f[1])
