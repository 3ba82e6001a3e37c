"""Choose the steps: greedy, the most expected information per second of stand time.

Each candidate is a frequency with a record length (1, 2, 4 or 8 times the stand's shortest
record there) and costs its record plus its settle from rest (:mod:`.settle`). The criterion
is Bayesian A-optimality over the prior's draws: ``Ψ = Σ_m Σ_j [A_m⁻¹]_jj / t_mj²`` over
the targeted parameters ``j``, with ``A_m`` the prior's information plus that of the steps
chosen so far at draw ``m`` and ``t_mj`` the target there. Each round adds the candidate of
the largest ``ΔΨ / cost``; it stops when, from the data alone (the report's estimator has no
prior), the targets are met in the ``quantile`` of the draws, or at the stand-time cap.
A frequency chosen twice becomes one step with the longer record (one settle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibid.planner.information import Information, fisher
from vibid.planner.settle import settle_s

#: record lengths a candidate may have, in multiples of the stand's shortest record there
RECORD_MULTIPLES = (1, 2, 4, 8)


@dataclass(frozen=True)
class Steps:
    """Planned steps in the order played (ascending frequency): candidate indices into the
    :class:`Information`, minimum record lengths and settle times, s."""

    index: np.ndarray
    record_s: np.ndarray
    settle_s: np.ndarray

    @property
    def stand_time_s(self) -> float:
        return float(np.sum(self.record_s) + np.sum(self.settle_s))


def data_std(info: Information, index, record_s) -> np.ndarray:
    """(m, p) standard uncertainty per draw of a test of these steps (inf where the steps
    cannot separate the parameters)."""
    F = fisher(info, np.asarray(index), record_s).sum(axis=1)
    out = np.full(F.shape[:2], np.inf)
    for m, Fm in enumerate(F):
        scale = np.sqrt(np.maximum(np.diag(Fm), 1e-300))
        Fn = Fm / np.outer(scale, scale)
        w = np.linalg.eigvalsh(Fn)
        if w.min() > 1e-12 * w.max():
            out[m] = np.sqrt(np.diag(np.linalg.inv(Fn))) / scale
    return out


def met(std: np.ndarray, targets_std: np.ndarray, targeted, quantile: float) -> float:
    """The ``quantile`` over draws of the worst ratio std / target: ≤ 1 is met."""
    worst = np.max(std[:, targeted] / targets_std, axis=1)
    return float(np.quantile(worst, quantile))


def sequence_settle(
    info: Information, index, record_s, *, floor_s: float, cap_s: float, quantile: float
) -> np.ndarray:
    """Settle time of each step played in this order, s: the quantile over draws."""
    out = []
    for k, (i, T) in enumerate(zip(index, record_s)):
        prev = None if k == 0 else info.frequency_hz[index[k - 1]]
        per_draw = [
            settle_s(
                info.frequency_hz[i],
                prev,
                info.s_1s[m, i] / np.sqrt(T),
                T,
                info.f_n[m],
                info.peak[m],
                info.beta[m],
            )
            for m in range(len(info.beta))
        ]
        out.append(np.clip(np.quantile(per_draw, quantile), floor_s, cap_s))
    return np.asarray(out)


def greedy(
    info: Information,
    candidates,
    shortest_record_s,
    targets_std: np.ndarray,
    targeted,
    prior_information: np.ndarray,
    *,
    floor_s: float,
    cap_s: float,
    quantile: float,
    settle_quantile: float,
    max_stand_time_s: float,
    start=(),
    max_steps: int = 400,
    measured: tuple = ((), ()),
) -> Steps:
    """The steps (see the module docstring). ``candidates``: indices into ``info``;
    ``shortest_record_s`` (len(candidates),); ``targets_std`` (m, len(targeted));
    ``prior_information`` (m, p, p); ``start``: positions in ``candidates`` taken first, at
    their shortest record (a coarse sweep: the global search needs the resonances found,
    which local information does not see); ``measured``: (indices into ``info``, record
    lengths) of steps already measured (an adaptive campaign's: their information is in
    ``prior_information`` too), counted when the targets are checked; ``max_steps``: new
    steps at most (a batch)."""
    k_of, T, cost = _candidate_costs(
        info, candidates, shortest_record_s, floor_s, cap_s, settle_quantile
    )
    F_c = fisher(info, k_of, T)  # (m, C, p, p)
    A = prior_information.copy()
    chosen: dict[int, float] = {}
    spent = 0.0
    for c in np.unique(np.asarray(start, int)) * len(RECORD_MULTIPLES):  # the multiple 1 of each
        A = A + F_c[:, c]
        chosen[int(k_of[c])] = float(T[c])
        spent += cost[c]
    m_index, m_record = (np.asarray(a) for a in measured)
    while len(chosen) < max_steps and spent < max_stand_time_s:
        c = _best_candidate(A, F_c, cost, targets_std, targeted)
        A = A + F_c[:, c]
        k = int(k_of[c])
        spent += T[c] + (0.0 if k in chosen else cost[c] - T[c])
        chosen[k] = chosen.get(k, 0.0) + T[c]  # the record lengthens: its e² counts once
        index = _in_play_order(info, chosen)
        every = np.concatenate([m_index, index]).astype(int)
        record = np.concatenate([m_record, [chosen[i] for i in index]])
        if met(data_std(info, every, record), targets_std, targeted, quantile) <= 1.0:
            break
    index = _in_play_order(info, chosen)
    record = np.array([chosen[i] for i in index])
    return Steps(
        index,
        record,
        sequence_settle(
            info, index, record, floor_s=floor_s, cap_s=cap_s, quantile=settle_quantile
        ),
    )


def _candidate_costs(
    info: Information, candidates, shortest_record_s, floor_s, cap_s, settle_quantile
):
    """Every candidate at every record multiple, ``C`` of them: its index into ``info``,
    its record length ``T`` (s) and its cost (s): the record plus the ``settle_quantile``
    over draws of its settle from rest, within [``floor_s``, ``cap_s``]."""
    cand = np.asarray(candidates)
    mult = np.asarray(RECORD_MULTIPLES, float)
    T = (np.asarray(shortest_record_s)[:, None] * mult[None, :]).ravel()  # (C,)
    k_of = np.repeat(cand, mult.size)  # (C,)
    s_T = info.s_1s[:, k_of] / np.sqrt(T)[None, :]  # (m, C)
    rest = np.array(
        [
            [
                settle_s(
                    info.frequency_hz[k],
                    None,
                    s_T[m, c],
                    T[c],
                    info.f_n[m],
                    info.peak[m],
                    info.beta[m],
                )
                for c, k in enumerate(k_of)
            ]
            for m in range(len(info.beta))
        ]
    )
    cost = T + np.clip(np.quantile(rest, settle_quantile, axis=0), floor_s, cap_s)
    return k_of, T, cost


def _psi(inv, targets_std: np.ndarray, targeted):
    """The criterion of ``inv`` (..., p, p) (module doc): ``Σ_j inv_jj / t²`` per draw."""
    d = np.diagonal(inv, axis1=-2, axis2=-1)[..., targeted]
    return np.sum(
        d / targets_std.reshape(targets_std.shape[0], *([1] * (d.ndim - 2)), -1) ** 2, axis=-1
    )


def _best_candidate(A, F_c, cost, targets_std: np.ndarray, targeted) -> int:
    """The candidate (column of ``F_c`` (m, C, p, p)) of the largest drop of the criterion
    summed over the draws, per second of its ``cost``, added to the information ``A``."""
    now = _psi(np.linalg.inv(A), targets_std, targeted).sum()
    after = _psi(np.linalg.inv(A[:, None] + F_c), targets_std, targeted).sum(axis=0)  # (C,)
    return int(np.argmax((now - after) / cost))


def _in_play_order(info: Information, chosen) -> np.ndarray:
    """The indices of ``chosen`` in the order played: ascending frequency."""
    return np.array(sorted(chosen, key=lambda i: info.frequency_hz[i]))
