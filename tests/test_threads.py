"""Work on two threads (vibid.identify.threads): a loop round's scores and refits taken in
the round's order, stopped where the round stops, a global search's population in equal
shares, and the loop's and the search's results the same to the last digit as on one
thread."""

import contextlib
import threading

import numpy as np
import pytest
from loop_data import F, data, declared_fit, strip_on

from vibid.errors import VibidError
from vibid.identify.loop import close_loop
from vibid.identify.threads import in_order, threads


def test_results_come_in_the_items_order_while_the_next_one_runs_at_once():
    second_done = threading.Event()
    running, most = [0], [0]
    lock = threading.Lock()

    def fn(i):
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        if i == 0:  # the first waits until the second has finished: they ran at once
            assert second_done.wait(timeout=60)
        if i == 1:
            second_done.set()
        with lock:
            running[0] -= 1
        return i * i

    assert list(in_order(fn, range(6), workers=2)) == [0, 1, 4, 9, 16, 25]
    assert most[0] == 2


def test_closing_early_starts_no_more_items_and_waits_for_the_running_one():
    started, finished = [], []

    def fn(i):
        started.append(i)
        finished.append(i)
        return i

    with contextlib.closing(in_order(fn, range(10), workers=2)) as runs:
        for i in runs:
            if i == 1:
                break
    # 0 and 1 consumed, 2 (and 3 at most) started early; nothing after it
    assert set(started) <= {0, 1, 2, 3} and sorted(finished) == sorted(started)


def test_an_error_is_raised_where_its_item_is_taken():
    def fn(i):
        if i == 2:
            raise ValueError("item 2")
        return i

    taken = []
    with pytest.raises(ValueError, match="item 2"):
        for i in in_order(fn, range(5), workers=2):
            taken.append(i)
    assert taken == [0, 1]


def test_one_thread_runs_every_item_on_the_calling_thread():
    me = threading.get_ident()
    assert list(in_order(lambda i: threading.get_ident() == me, range(3), workers=1)) == [
        True] * 3


def test_the_thread_count_is_read_from_the_environment(monkeypatch):
    monkeypatch.setenv("VIBID_THREADS", "1")
    assert threads() == 1
    monkeypatch.setenv("VIBID_THREADS", "two")
    with pytest.raises(VibidError, match="whole number"):
        threads()
    monkeypatch.setenv("VIBID_THREADS", "0")
    with pytest.raises(VibidError, match="1 or more"):
        threads()
    monkeypatch.delenv("VIBID_THREADS")
    assert 1 <= threads() <= 2


@pytest.mark.slow
def test_a_loop_on_two_threads_is_the_loop_on_one(monkeypatch):
    """Two undeclared effects (a channel delay and an elastic clamp): each round scores
    every candidate and refits several. Every stage, chi2 and verdict the same, bit for
    bit."""
    effects = {"tau_s": 2e-5, "k_theta_N_per_rad": 1.6e4}
    H, sd = data(effects, 11)
    declared = declared_fit(effects, 11)
    loops = {}
    for n in ("1", "2"):
        monkeypatch.setenv("VIBID_THREADS", n)
        loops[n] = close_loop(strip_on(), F, H, sd, seed=0, declared=declared)
    one, two = loops["1"], loops["2"]
    assert set(one.effects) == {"channel_delay", "clamp_compliance"}
    assert one.effects == two.effects
    for a, b in zip(one.stages, two.stages):
        assert a.result.chi2 == b.result.chi2
        np.testing.assert_array_equal(a.result.values, b.result.values)
        np.testing.assert_array_equal(a.result.std, b.result.std)
    assert [[(s.name, s.verdict) for s in r] for r in one.rounds] == [
        [(s.name, s.verdict) for s in r] for r in two.rounds]


def test_equal_shares_cover_the_population_in_one_shape():
    from vibid.identify.fit.global_search import equal_shares

    U = np.arange(45.0 * 3).reshape(45, 3)
    shares = equal_shares(U, 2)
    assert [s.shape for s in shares] == [(23, 3), (23, 3)]
    np.testing.assert_array_equal(np.concatenate(shares)[:45], U)
    np.testing.assert_array_equal(shares[1][-1], U[-1])  # the filler repeats the last row
    assert equal_shares(U, 1)[0] is U


def test_a_global_search_on_two_threads_is_the_search_on_one(monkeypatch):
    """A generation's population in two shares: every restart ends where it ended in one
    call, with the same chi2 to the last digit (scipy's evolution sees the same values)."""
    from vibid.identify.fit.data import fit_data
    from vibid.identify.fit.global_search import differential_evolution
    from vibid.identify.fit.problem import LeastSquaresProblem
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.model.forward import build_forward_model

    setup = strip_on()
    H, sd = data({}, 1)
    d = fit_data(F, H, sd, None)
    box = dict(setup.identification.bounds)
    fm = build_forward_model(setup, d.frequency_hz[d.used], model=setup.identification.model,
                             bounds=box)
    space = ParameterSpace.from_bounds(tuple(fm.parameter_names), fm.param.default_bounds(box))
    problem = LeastSquaresProblem(fm, d, space)
    found = {}
    for n in ("1", "2"):
        monkeypatch.setenv("VIBID_THREADS", n)
        found[n] = differential_evolution(problem, restarts=2, rng=3, max_generations=20)
    np.testing.assert_array_equal(found["1"].u, found["2"].u)
    np.testing.assert_array_equal(found["1"].loss, found["2"].loss)


def test_a_section_open_on_two_threads_at_once_counts_on_each():
    """Profile sections are per thread: the second thread's section is not taken for one
    nested in the first's (it was, and counted once), and a section inside itself on one
    thread still counts once."""
    from vibid.identify.profile import recording, section

    both_inside = threading.Barrier(2)

    def work(_):
        with section("local fits"):
            both_inside.wait(timeout=60)
            with section("local fits"):
                pass

    with recording() as prof:
        list(in_order(work, range(2), workers=2))
    assert prof.calls["local fits"] == 2
