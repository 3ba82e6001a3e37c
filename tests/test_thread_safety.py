"""Identifications on threads (a batch's sessions on Prefect's thread runner) share the
plate element of a mesh and the profile: the element's basis evaluated by two threads at
once gives each its own matrices, and a profile section open on two threads counts on
each."""

import sys
import threading

import numpy as np
from skfem import Basis

from vibid.identify.engine.profile import recording, section
from vibid.identify.model.disc import assemble_disc
from vibid.identify.model.elements import ElementTriArgyrisLocal
from vibid.identify.model.mesh import plate_mesh


def _on_threads(fn, args):
    out = [None] * len(args)

    def run(k):
        out[k] = fn(args[k])

    threads = [threading.Thread(target=run, args=(k,)) for k in range(len(args))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
    return out


def test_two_threads_evaluating_one_elements_basis_get_each_their_own_matrices():
    """The element keeps the monomials of its last points on its one instance: two threads
    at two sensor discs once mixed theirs (a closed-loop score failed with "operands could
    not be broadcast together"); under the element's lock each gets the matrices it gets
    alone. A short switch interval makes the threads interleave often."""
    from plate_helpers import strip_setup
    from vibid.identify.model.assembly import Geometry
    from vibid.identify.model.mesh import discretisation

    g = Geometry.from_setup(strip_setup())
    mesh = plate_mesh(g.length_m, g.width_m, discretisation(g, "default"))
    basis = Basis(mesh, ElementTriArgyrisLocal(), intorder=10)
    centres = [
        np.array([0.8 * g.length_m, 0.5 * g.width_m]),
        np.array([0.5 * g.length_m, 0.3 * g.width_m]),
    ] * 3
    alone = [assemble_disc(basis, c, 0.003)[0].toarray() for c in centres]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        together = _on_threads(lambda c: assemble_disc(basis, c, 0.003)[0].toarray(), centres)
    finally:
        sys.setswitchinterval(interval)
    for a, b in zip(alone, together):
        np.testing.assert_array_equal(a, b)


def test_a_section_open_on_two_threads_at_once_counts_on_each():
    """Profile sections are per thread: the second thread's section was taken for one
    nested in the first's, and counted once; a section inside itself on one thread still
    counts once."""
    both_inside = threading.Barrier(2)

    def work(_):
        with section("local fits"):
            both_inside.wait(timeout=60)
            with section("local fits"):
                pass

    with recording() as prof:
        _on_threads(work, [0, 1])
    assert prof.calls["local fits"] == 2
