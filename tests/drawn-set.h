/*
 * What a frame drew (tw_world_drawn()) as a sorted set of clusters, for the
 * GL tests that compare one method's set with another's.
 */
#ifndef TW_TESTS_DRAWN_SET_H
#define TW_TESTS_DRAWN_SET_H

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/runtime.h"

/* By cell, then prototype, then cluster. */
static int compare_drawn(const void *a, const void *b)
{
    const struct tw_drawn_cluster *x = a, *y = b;
    if (x->cell.i != y->cell.i) return x->cell.i < y->cell.i ? -1 : 1;
    if (x->cell.j != y->cell.j) return x->cell.j < y->cell.j ? -1 : 1;
    if (x->prototype != y->prototype) return x->prototype < y->prototype ? -1 : 1;
    return (x->cluster > y->cluster) - (x->cluster < y->cluster);
}

/* A sorted copy of the *n clusters w's last frame drew; the caller frees it.
 * Out of memory ends the test (exit 1): an empty set would pass checks it
 * should not. */
static struct tw_drawn_cluster *copy_drawn(struct tw_world *w, size_t *n)
{
    const struct tw_drawn_cluster *d = tw_world_drawn(w, n);
    struct tw_drawn_cluster *c = malloc(sizeof(*c) * (*n ? *n : 1));
    if (!c) {
        fprintf(stderr, "out of memory copying %zu drawn clusters\n", *n);
        exit(1);
    }
    memcpy(c, d, sizeof(*c) * *n);
    qsort(c, *n, sizeof(*c), compare_drawn);
    return c;
}

/* The sorted set[0, n) holds a cluster twice: drawn twice in one frame. */
static bool has_duplicate(const struct tw_drawn_cluster *set, size_t n)
{
    for (size_t q = 1; q < n; q++)
        if (compare_drawn(&set[q - 1], &set[q]) == 0)
            return true;
    return false;
}

/* Every element of sub (sorted) is in all (sorted). */
static bool includes(const struct tw_drawn_cluster *all, size_t na,
                     const struct tw_drawn_cluster *sub, size_t ns)
{
    size_t k = 0;
    for (size_t q = 0; q < ns; q++) {
        while (k < na && compare_drawn(&all[k], &sub[q]) < 0)
            k++;
        if (k == na || compare_drawn(&all[k], &sub[q]) != 0)
            return false;
    }
    return true;
}

#endif
