"""Work on two threads (vibid.identify.engine.threads): a loop round's scores and refits taken in
the round's order, stopped where the round stops; compiled JAX code on one thread at a time
(the JAX turn), the numpy-only work beside it; and the loop's results the same to the last
digit as on one thread."""

import contextlib
import sys
import threading
import time

import numpy as np
import pytest

from loop_data import F, data, declared_fit, strip_on
from vibid.errors import VibidError
from vibid.identify.engine import threads as th
from vibid.identify.engine.threads import holds_turn, in_order, jax_turn, numpy_only, threads
from vibid.identify.loop import close_loop


class Overlap:
    """How many threads were inside a block at once, at most."""

    def __init__(self):
        self.now, self.most, self.lock = 0, 0, threading.Lock()

    @contextlib.contextmanager
    def inside(self, seconds=0.02):
        with self.lock:
            self.now += 1
            self.most = max(self.most, self.now)
        try:
            time.sleep(seconds)  # long enough for the other thread to arrive
            yield
        finally:
            with self.lock:
                self.now -= 1


def test_the_turn_is_held_by_one_thread_while_numpy_only_work_overlaps():
    """Each item runs 'JAX' (its turn held) and numpy-only work: the JAX parts of eight
    items never ran at once, and the numpy-only parts of two met (each waits at a barrier
    for the other, which only a lent turn lets in; whichever worker gets the turn first)."""
    jax_part = Overlap()
    both = threading.Barrier(2, timeout=30)

    @numpy_only
    def assemble(i):
        assert not holds_turn()
        if i < 2:
            both.wait()  # broken (an error) unless the other item's numpy part came in

    def fn(i):
        assert holds_turn()
        with jax_part.inside():
            pass
        assemble(i)
        assert holds_turn()
        with jax_part.inside():
            pass
        return i * i

    assert list(in_order(fn, range(8), workers=2)) == [i * i for i in range(8)]
    assert jax_part.most == 1
    assert not holds_turn()


def test_the_consuming_thread_takes_turns_with_the_items():
    """Between two items the consuming thread holds the turn (it judges with JAX), and no
    item's JAX part runs then."""
    jax_part = Overlap()

    def fn(i):
        with jax_part.inside():
            return i

    for _ in in_order(fn, range(6), workers=2):
        assert holds_turn()
        with jax_part.inside(0.05):
            pass
    assert jax_part.most == 1
    assert not holds_turn()


def test_the_turn_is_re_entrant_and_lent_only_by_its_holder():
    with jax_turn():
        with jax_turn():
            assert holds_turn()
        assert holds_turn()
        numpy_only(lambda: None)()
        assert holds_turn()
    assert not holds_turn()
    assert numpy_only(lambda: holds_turn())() is False  # nothing to lend: still runs


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
    assert not holds_turn()


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
    assert not holds_turn()


def test_one_thread_runs_every_item_on_the_calling_thread_without_the_turn():
    me = threading.get_ident()
    assert (
        list(in_order(lambda i: (threading.get_ident() == me, holds_turn()), range(3), workers=1))
        == [(True, False)] * 3
    )


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


def _jax_calls_while_lent(monkeypatch) -> set:
    """Watch every thread while it lends its turn: the Python functions of JAX (or of
    vibid's persisted programs) it calls are collected (a numpy-only mark on a function
    that runs compiled code would let two programs run at once)."""
    seen = set()
    lent = th.numpy_section

    def hook(frame, event, arg):
        if event == "call" and frame.f_code.co_name != "_xla_gc_callback":  # Python's gc
            name = frame.f_code.co_filename
            if "/jax/" in name or "/jaxlib/" in name or name.endswith("persist.py"):
                seen.add(f"{name}:{frame.f_code.co_name}")

    @contextlib.contextmanager
    def watched():
        with lent():
            before = sys.getprofile()
            sys.setprofile(hook)
            try:
                yield
            finally:
                sys.setprofile(before)

    monkeypatch.setattr(th, "numpy_section", watched)
    return seen


@pytest.mark.slow
def test_a_loop_on_two_threads_is_the_loop_on_one(monkeypatch):
    """Two undeclared effects (a channel delay and an elastic clamp): each round scores
    every candidate and refits several. Every stage, chi2 and verdict the same, bit for
    bit; and no JAX code ran where a thread had lent its turn."""
    effects = {"tau_s": 2e-5, "k_theta_N_per_rad": 1.6e4}
    H, sd = data(effects, 11)
    declared = declared_fit(effects, 11)
    loops = {}
    for n in ("1", "2"):
        monkeypatch.setenv("VIBID_THREADS", n)
        if n == "2":
            seen = _jax_calls_while_lent(monkeypatch)
        loops[n] = close_loop(strip_on(), F, H, sd, seed=0, declared=declared)
    one, two = loops["1"], loops["2"]
    assert set(one.effects) == {"channel_delay", "clamp_compliance"}
    assert one.effects == two.effects
    for a, b in zip(one.stages, two.stages):
        assert a.result.chi2 == b.result.chi2
        np.testing.assert_array_equal(a.result.values, b.result.values)
        np.testing.assert_array_equal(a.result.std, b.result.std)
    assert [[(s.name, s.verdict) for s in r] for r in one.rounds] == [
        [(s.name, s.verdict) for s in r] for r in two.rounds
    ]
    assert seen == set()


def test_an_in_order_inside_an_item_runs_on_that_items_thread():
    """A polish inside a loop's refit: the inner items run one after the other on the
    outer item's worker thread (no third thread waiting for the turn)."""

    def inner(j):
        return threading.get_ident()

    def outer(i):
        me = threading.get_ident()
        return all(t == me for t in in_order(inner, range(3), workers=2))

    assert list(in_order(outer, range(3), workers=2)) == [True] * 3


def test_a_lock_is_waited_for_with_the_turn_lent():
    """The lock's holder needs the turn to finish (it compiled with the turn lent): the
    waiter lends it while it waits, or neither would go on."""
    from vibid.identify.engine.threads import holding

    lock, order, locked = threading.Lock(), [], threading.Event()

    def holder(i):
        if i == 0:
            with holding(lock):
                locked.set()
                numpy_only(lambda: time.sleep(0.1))()  # the turn lent: the other waits
                order.append("holder done")  # with the turn back
        else:  # whichever worker the turn reaches first, the lock is the holder's first
            assert numpy_only(lambda: locked.wait(timeout=30))()
            with holding(lock):
                order.append("waiter in")
        return i

    results = []
    run = threading.Thread(
        target=lambda: results.extend(in_order(holder, range(2), workers=2)), daemon=True
    )
    run.start()
    run.join(timeout=30)
    assert not run.is_alive(), "deadlocked: the waiter held the turn the holder needed"
    assert results == [0, 1]
    assert order == ["holder done", "waiter in"]
