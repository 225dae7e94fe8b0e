/* Booleans of whole-line hit lists: the C form of tracer/intersect/csg.py's combine, one ray at a time.
 *
 * The two children's sorted hits are merged (left first on equal times); hits whose error
 * intervals t +- err overlap form one event group, decided by the inside/outside states before and after the whole group;
 * a child entered and left within one group (a zero-thickness sheet) is kept, as an enter/exit pair at
 * the same time, where the boolean would show it. */
#ifndef RT_CSG_H
#define RT_CSG_H

#include "core.h"
#include "numeric.h"

typedef struct {
    Hit *h;
    int64_t n, cap;
    int inside;  /* inside the solid at t = -inf */
} HitList;

static inline int csg_state(int op, int left, int right)
{
    switch (op) {
    case OP_UNION: return left || right;
    case OP_INTERSECTION: return left && right;
    default: return left && !right;
    }
}

/* `out` needs room for 2 (left->n + right->n) hits.  Returns the number written; sets *inside. */
static int64_t csg_combine(int op, const HitList *left, const HitList *right, Hit *out, int *inside)
{
    int state[2] = {left->inside, right->inside};
    int before[2] = {state[0], state[1]};
    int entered[2] = {0, 0}, left_again[2] = {0, 0};
    *inside = csg_state(op, state[0], state[1]);
    int64_t i = 0, j = 0, n = 0, nl = left->n, nr = right->n;
    int first_in_group = 1;
    Hit rep;
    while (i < nl || j < nr) {
        int from_right = !(i < nl && (j >= nr || left->h[i].t <= right->h[j].t));
        Hit cur = from_right ? right->h[j++] : left->h[i++];
        if (from_right && op == OP_DIFFERENCE) {  /* leaving the subtracted solid enters the result */
            cur.n[0] = -cur.n[0];
            cur.n[1] = -cur.n[1];
            cur.n[2] = -cur.n[2];
        }
        int ends_group = 1;
        if (i < nl || j < nr) {
            const Hit *next = (i < nl && (j >= nr || left->h[i].t <= right->h[j].t)) ? &left->h[i] : &right->h[j];
            ends_group = !(next->t - cur.t <= cur.err + next->err);  /* error intervals apart */
        }
        int c = from_right;
        if (cur.entering) {
            entered[c] = 1;
            state[c] = 1;
        } else {
            left_again[c] |= entered[c] || !before[c];
            state[c] = 0;
        }
        int res_before = csg_state(op, before[0], before[1]);
        int res_after = csg_state(op, state[0], state[1]);
        /* Prefer, as the group's surface, a hit whose own crossing agrees with the result's change. */
        if (first_in_group || (cur.entering != 0) == res_after)
            rep = cur;
        if (ends_group) {
            int changes = res_before != res_after;
            int sheet_left = entered[0] && left_again[0] && !before[0] && !state[0] && csg_state(op, 1, before[1]);
            int sheet_right = entered[1] && left_again[1] && !before[1] && !state[1] && csg_state(op, before[0], 1);
            int sheet = !res_before && !res_after && (sheet_left || sheet_right);
            if (changes || sheet) {
                out[n] = rep;
                out[n].entering = sheet ? 1 : res_after;
                n++;
            }
            if (sheet) {
                out[n] = rep;
                out[n].entering = 0;
                n++;
            }
            before[0] = state[0];
            before[1] = state[1];
            entered[0] = entered[1] = 0;
            left_again[0] = left_again[1] = 0;
        }
        first_in_group = ends_group;
    }
    /* Groups come in time order, so the output is sorted already; a stable pass keeps that certain. */
    for (int64_t a = 1; a < n; a++) {
        Hit x = out[a];
        int64_t b = a;
        while (b > 0 && out[b - 1].t > x.t) {
            out[b] = out[b - 1];
            b--;
        }
        out[b] = x;
    }
    return n;
}

#endif
