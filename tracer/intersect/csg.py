"""Booleans of hit lists (the lecture's CSG): merge the children's sorted hits and keep the places
where the combined inside/outside value changes.

Robustness, the part the lecture leaves out:

* Hits whose error intervals ``t +- error`` (tracer.numerics) overlap are one *event group*: coincident
  faces (a difference that shares a face, the union of two identical spheres) are decided by the states
  before and after the whole group, so they leave neither a spurious sheet nor a hole.  Nothing else
  merges: how far apart two distinct surfaces may be is set by how well their hits are known, not by the
  coordinates' size.
* A child entered and left within one group is a zero-thickness sheet (the square, which has no inside):
  it is kept where the boolean would show it, as an enter/exit pair at the same time.
"""
from __future__ import annotations

import numpy as np

from .hits import HitArrays

OPERATIONS = {
    "union": np.logical_or,
    "intersection": np.logical_and,
    "difference": lambda left, right: left & ~right,
}


def sheet_to_pairs(hits: HitArrays) -> HitArrays:
    """A thin shape's single crossings become enter+exit pairs at the same time (a zero-thickness solid)."""
    n, k = hits.t.shape
    order = np.repeat(np.arange(k), 2)[None, :].repeat(n, axis=0)
    pairs = hits.take(order)
    pairs.entering[:, 0::2] = np.isfinite(pairs.t[:, 0::2])
    pairs.entering[:, 1::2] = False
    return pairs


def combine(op: str, left: HitArrays, right: HitArrays) -> HitArrays:
    """The hits of ``left op right`` for the same N rays (both children sorted, whole-line hits)."""
    combine_states = OPERATIONS[op]
    n = left.count
    k_left, k_right = left.slots, right.slots
    k = k_left + k_right
    t = np.concatenate([left.t, right.t], axis=1)
    order = np.argsort(t, axis=1, kind="stable")
    rows = np.arange(n)[:, None]
    t = t[rows, order]
    from_right = (order >= k_left)
    entering = np.concatenate([left.entering, right.entering], axis=1)[rows, order]
    normal = np.concatenate([left.normal, right.normal], axis=1)[rows, order]
    if op == "difference":  # leaving the subtracted solid enters the result: its normals turn round
        normal = np.where(from_right[..., None], -normal, normal)
    part = np.concatenate([left.part, right.part], axis=1)[rows, order]
    uv = np.concatenate([left.uv, right.uv], axis=1)[rows, order]
    shape = np.concatenate([left.shape, right.shape], axis=1)[rows, order]
    error = np.concatenate([left.error, right.error], axis=1)[rows, order]
    offset = np.concatenate([left.offset, right.offset], axis=1)[rows, order]

    finite = np.isfinite(t)
    # A slot ends its group when the next slot's error interval does not overlap its own (or is absent).
    ends_group = np.ones((n, k), dtype=bool)
    with np.errstate(invalid="ignore"):
        gap = np.diff(t, axis=1)  # inf - inf between unused slots is NaN: not "the same time"
        ends_group[:, :-1] = ~(gap <= error[:, :-1] + error[:, 1:])

    out = HitArrays.empty(n, 2 * k)
    state = [left.inside_at_start.copy(), right.inside_at_start.copy()]
    out.inside_at_start = combine_states(state[0], state[1])
    before = [s.copy() for s in state]
    entered = [np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)]
    left_again = [np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)]
    rep = np.zeros(n, dtype=np.int64)  # slot whose surface represents the group's change
    for j in range(k):
        live = finite[:, j]
        for child in (0, 1):
            mine = live & (from_right[:, j] == bool(child))
            enters = mine & entering[:, j]
            leaves = mine & ~entering[:, j]
            left_again[child] |= leaves & (entered[child] | ~before[child])
            entered[child] |= enters
            state[child] = np.where(enters, True, np.where(leaves, False, state[child]))
        res_before = combine_states(before[0], before[1])
        res_after = combine_states(state[0], state[1])
        # Prefer, as the group's surface, a slot whose own crossing agrees with the result's change.
        agrees = live & (entering[:, j] == res_after)
        first_in_group = np.ones(n, dtype=bool) if j == 0 else ends_group[:, j - 1]
        rep = np.where(first_in_group | agrees, j, rep)
        done = ends_group[:, j] & live
        changes = done & (res_before != res_after)
        sheet_left = entered[0] & left_again[0] & ~before[0] & ~state[0] & combine_states(True, before[1])
        sheet_right = entered[1] & left_again[1] & ~before[1] & ~state[1] & combine_states(before[0], True)
        sheet = done & ~res_before & ~res_after & (sheet_left | sheet_right)
        r = rep
        for slot, emit, enters_flag in ((2 * j, changes | sheet, np.where(sheet, True, res_after)),
                                        (2 * j + 1, sheet, np.zeros(n, dtype=bool))):
            idx = np.nonzero(emit)[0]
            out.t[idx, slot] = t[idx, r[idx]]
            out.entering[idx, slot] = enters_flag[idx]
            out.normal[idx, slot] = normal[idx, r[idx]]
            out.part[idx, slot] = part[idx, r[idx]]
            out.uv[idx, slot] = uv[idx, r[idx]]
            out.shape[idx, slot] = shape[idx, r[idx]]
            out.error[idx, slot] = error[idx, r[idx]]
            out.offset[idx, slot] = offset[idx, r[idx]]
        # The next group starts from here.
        for child in (0, 1):
            before[child] = np.where(done, state[child], before[child])
            entered[child] &= ~done
            left_again[child] &= ~done
    return out.sorted().trimmed()
